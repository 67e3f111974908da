/* What every test program shares: a check that exits with a message, and
 * a whole file read into memory. */
#ifndef AOBAKE_TEST_H
#define AOBAKE_TEST_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "aobake_rt.h"

#define EXPECT(cond, ...) do { if (!(cond)) { fprintf(stderr, __VA_ARGS__); fputc('\n', stderr); exit(1); } } while (0)

static inline void *slurp(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    EXPECT(f, "cannot open %s", path);
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    void *data = malloc((size_t)n);
    EXPECT(fread(data, 1, (size_t)n, f) == (size_t)n, "cannot read %s", path);
    fclose(f);
    *len = (size_t)n;
    return data;
}

/* Sets each node a pose file names (lines "name<TAB>tx ty tz rx ry rz rw
 * sx sy sz") on `ao`, by name, as an engine's animation gives it; the
 * number of nodes set. */
static inline int set_pose(AobakeVertexAo *ao, const char *path) {
    FILE *pose = fopen(path, "r");
    EXPECT(pose, "cannot open %s", path);
    char line[1024];
    int set = 0;
    while (fgets(line, sizeof line, pose)) {
        char *tab = strchr(line, '\t');
        EXPECT(tab, "bad pose line: %s", line);
        *tab = '\0';
        int64_t node = aobake_vertex_ao_node(ao, line);
        EXPECT(node >= 0, "%s", aobake_last_error());
        AobakeTransform rest, t;
        EXPECT(aobake_vertex_ao_rest(ao, (size_t)node, &rest), "%s", aobake_last_error());
        float *v[10] = {&t.translation[0], &t.translation[1], &t.translation[2],
                        &t.rotation[0], &t.rotation[1], &t.rotation[2], &t.rotation[3],
                        &t.scale[0], &t.scale[1], &t.scale[2]};
        char *at = tab + 1;
        for (int i = 0; i < 10; i++) {
            char *end;
            *v[i] = strtof(at, &end);
            EXPECT(end != at, "bad number in pose line for %s", line);
            at = end;
        }
        EXPECT(aobake_vertex_ao_set_local(ao, (size_t)node, &t), "%s", aobake_last_error());
        set++;
    }
    fclose(pose);
    return set;
}

#endif
