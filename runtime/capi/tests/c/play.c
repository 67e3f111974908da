/* What an engine plugin does with aobake's C ABI, as a test drives it:
 *
 *   play ASSET POSE OUT
 *
 * reads ASSET, finds each node POSE names (lines "name<TAB>tx ty tz rx ry
 * rz rw sx sy sz"), sets its local transform, and writes the pose's
 * weights then every vertex's AO to OUT as raw little-endian floats. It
 * also checks the error paths: a file that is no asset, a node the rig
 * lacks, a buffer of the wrong length. Exits non-zero with a message on
 * anything unexpected. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "aobake_rt.h"
#include "test.h"

int main(int argc, char **argv) {
    EXPECT(argc == 4, "usage: play ASSET POSE OUT");

    /* Not an asset: NULL, and the reason. */
    const uint8_t junk[] = "not an asset at all";
    EXPECT(aobake_vertex_ao_open(junk, sizeof junk) == NULL, "junk opened");
    EXPECT(aobake_last_error() && strstr(aobake_last_error(), "not an aobake asset"),
           "junk: %s", aobake_last_error());

    size_t len;
    void *bytes = slurp(argv[1], &len);
    AobakeVertexAo *ao = aobake_vertex_ao_open((const uint8_t *)bytes, len);
    free(bytes); /* the handle keeps its own copy */
    EXPECT(ao, "open: %s", aobake_last_error());

    size_t vertices = aobake_vertex_ao_vertices(ao);
    size_t weights = aobake_vertex_ao_weight_count(ao);
    EXPECT(vertices > 0 && weights > 0, "empty asset");
    EXPECT(aobake_vertex_ao_node(ao, "no such node") == -1, "found a missing node");
    EXPECT(strstr(aobake_last_error(), "no node named"), "missing node: %s", aobake_last_error());

    /* The pose: each node by name, its local transform. */
    int set = set_pose(ao, argv[2]);
    EXPECT(set > 0, "the pose set no node");
    AobakeTransform nan = {{0.0f / 0.0f, 0, 0}, {0, 0, 0, 1}, {1, 1, 1}};
    EXPECT(!aobake_vertex_ao_set_local(ao, 0, &nan), "a NaN transform was taken");
    EXPECT(!aobake_vertex_ao_set_local(ao, aobake_vertex_ao_node_count(ao), &nan), "a node past the end was taken");

    float *w = malloc(weights * sizeof *w);
    float *a = malloc(vertices * sizeof *a);
    EXPECT(!aobake_vertex_ao_evaluate(ao, a, vertices - 1), "a short buffer was filled");
    EXPECT(aobake_vertex_ao_weights(ao, w, weights), "%s", aobake_last_error());
    EXPECT(aobake_vertex_ao_evaluate(ao, a, vertices), "%s", aobake_last_error());

    FILE *out = fopen(argv[3], "wb");
    EXPECT(out, "cannot write %s", argv[3]);
    fwrite(w, sizeof *w, weights, out);
    fwrite(a, sizeof *a, vertices, out);
    fclose(out);
    printf("%zu weights, %zu vertices, %d nodes set\n", weights, vertices, set);
    free(w);
    free(a);
    aobake_vertex_ao_free(ao);
    return 0;
}
