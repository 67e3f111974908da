/* What an engine plugin does with a texel asset through aobake's C ABI,
 * as a test drives it:
 *
 *   texel ASSET POSE OUT
 *
 * opens ASSET as a texel asset, sets the pose POSE names (lines
 * "name<TAB>tx ty tz rx ry rz rw sx sy sz") through the handle
 * aobake_texel_pose gives, and writes to OUT as raw little-endian floats:
 * the pose's weights, the AO sampled at every atlas vertex's UV, and the
 * first basis texture. It checks the sizes the atlas's arrays report and
 * the error paths too. Exits non-zero with a message on anything
 * unexpected. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "aobake_rt.h"
#include "test.h"

int main(int argc, char **argv) {
    EXPECT(argc == 4, "usage: texel ASSET POSE OUT");
    size_t len;
    void *bytes = slurp(argv[1], &len);
    /* A texel asset is not a vertex asset, and the other way round. */
    EXPECT(aobake_vertex_ao_open((const uint8_t *)bytes, len) == NULL, "opened as a vertex asset");
    AobakeTexel *texel = aobake_texel_open((const uint8_t *)bytes, len);
    free(bytes);
    EXPECT(texel, "open: %s", aobake_last_error());
    AobakeVertexAo *pose = aobake_texel_pose(texel);
    EXPECT(pose, "pose: %s", aobake_last_error());

    EXPECT(set_pose(pose, argv[2]) > 0, "the pose set no node");

    size_t weights = aobake_vertex_ao_weight_count(pose);
    uint32_t width, height;
    EXPECT(aobake_texel_atlas_size(texel, &width, &height), "%s", aobake_last_error());
    size_t vertices = aobake_texel_atlas_vertex_count(texel);
    size_t words;
    EXPECT(aobake_texel_atlas_words(texel, AOBAKE_TEXEL_ATLAS_VERTEX_OF, NULL, 0, &words), "%s", aobake_last_error());
    EXPECT(words == vertices, "%zu vertex sources for %zu vertices", words, vertices);
    EXPECT(aobake_texel_atlas_words(texel, AOBAKE_TEXEL_ATLAS_TRIANGLES, NULL, 0, &words) && words % 3 == 0 && words > 0,
           "triangles: %zu words", words);
    uint32_t *triangles = malloc(words * sizeof *triangles);
    EXPECT(!aobake_texel_atlas_words(texel, AOBAKE_TEXEL_ATLAS_TRIANGLES, triangles, words - 1, &words), "a short buffer was filled");
    EXPECT(aobake_texel_atlas_words(texel, AOBAKE_TEXEL_ATLAS_TRIANGLES, triangles, words, &words), "%s", aobake_last_error());
    for (size_t i = 0; i < words; i++) EXPECT(triangles[i] < vertices, "a triangle past the vertices");
    EXPECT(!aobake_texel_atlas_words(texel, 7, NULL, 0, &words), "an unknown array was given");
    EXPECT(aobake_texel_atlas_words(texel, AOBAKE_TEXEL_ATLAS_TEXELS, NULL, 0, &words) && words > 0, "no texels");

    float *w = malloc(weights * sizeof *w);
    EXPECT(aobake_vertex_ao_weights(pose, w, weights), "%s", aobake_last_error());
    float *uvs = malloc(2 * vertices * sizeof *uvs);
    EXPECT(aobake_texel_atlas_uvs(texel, uvs, 2 * vertices), "%s", aobake_last_error());
    float *ao = malloc(vertices * sizeof *ao);
    EXPECT(aobake_texel_sample(texel, uvs, vertices, ao, vertices), "%s", aobake_last_error());
    size_t texels = (size_t)width * height;
    float *basis = malloc(texels * sizeof *basis);
    EXPECT(!aobake_texel_basis(texel, weights, basis, texels), "a layer past the weights was given");
    EXPECT(strstr(aobake_last_error(), "basis textures"), "%s", aobake_last_error());
    EXPECT(aobake_texel_basis(texel, 0, basis, texels), "%s", aobake_last_error());

    FILE *out = fopen(argv[3], "wb");
    EXPECT(out, "cannot write %s", argv[3]);
    fwrite(w, sizeof *w, weights, out);
    fwrite(ao, sizeof *ao, vertices, out);
    fwrite(basis, sizeof *basis, texels, out);
    fclose(out);
    printf("%zu weights, %zu atlas vertices, %u x %u texels\n", weights, vertices, width, height);
    free(w); free(uvs); free(ao); free(basis); free(triangles);
    aobake_texel_free(texel);
    return 0;
}
