/* What every test program shares: a check that exits with a message, and
 * a whole file read into memory. */
#ifndef AOBAKE_TEST_H
#define AOBAKE_TEST_H

#include <stdio.h>
#include <stdlib.h>

#define EXPECT(cond, ...) do { if (!(cond)) { fprintf(stderr, __VA_ARGS__); fputc('\n', stderr); exit(1); } } while (0)

static void *slurp(const char *path, size_t *len) {
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

#endif
