/* The lookups in space through aobake's C ABI, as a test drives them:
 *
 *   lookups cubemap ASSET SECONDS POINTS OUT
 *   lookups grid ASSET PALETTE POINTS OUT
 *
 * POINTS has a receiver a line: "px py pz nx ny nz part kind" (part -1
 * for none; kind the vertex index, -1 for the ground, -2 for another
 * surface; the cubemap reads the point only); PALETTE a 4 x 4
 * column-major matrix a line (16 numbers). Writes two floats per receiver
 * to OUT, raw little-endian, all of the first kind and then all of the
 * second: for a cubemap, the occlusion and the AO on its static ground
 * (aobake_cubemap_ground_ao); for a grid, the grids alone
 * (aobake_grid_occlusion) and the AO on the static base
 * (aobake_grid_ao). Then the asset's GPU form as an engine uploads it,
 * raw 32-bit words: for a cubemap, its AobakeCubemapGpuParams, the phase at
 * SECONDS and the arrays AOBAKE_CUBEMAP_GPU_TEXELS and _GROUND; for a
 * grid, its AobakeGridGpuParams, each part's joint, the arrays
 * AOBAKE_GRID_GPU_INFOS, _CELLS, _VERTEX_OFFSETS and _GROUND, and the
 * parts' poses for PALETTE. Also checks the ABI version, that the other
 * kind of asset and a short palette are refused with a reason, and that a
 * NaN point is refused. Exits non-zero on anything unexpected. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "aobake_rt.h"
#include "test.h"

/* Every number of a text file, in order. */
static float *numbers(const char *path, size_t *count) {
    FILE *f = fopen(path, "r");
    EXPECT(f, "cannot open %s", path);
    size_t cap = 1024, n = 0;
    float *v = malloc(cap * sizeof *v);
    float x;
    while (fscanf(f, "%f", &x) == 1) {
        if (n == cap) { cap *= 2; v = realloc(v, cap * sizeof *v); }
        v[n++] = x;
    }
    fclose(f);
    *count = n;
    return v;
}

/* Writes array `which` of a GPU form, sized by a first call, to f. */
#define DUMP_WORDS(f, get, handle, which) do { \
    size_t words_ = 0; \
    EXPECT(get(handle, which, NULL, 0, &words_), "size of %s: %s", #which, aobake_last_error()); \
    uint32_t *w_ = malloc(words_ * sizeof *w_ + 1); \
    EXPECT(get(handle, which, w_, words_, &words_), "%s: %s", #which, aobake_last_error()); \
    fwrite(w_, sizeof *w_, words_, f); \
    free(w_); \
} while (0)

int main(int argc, char **argv) {
    EXPECT(argc == 6, "usage: lookups cubemap|grid ASSET SECONDS|PALETTE POINTS OUT");
    EXPECT(aobake_rt_abi_version() == AOBAKE_RT_ABI_VERSION, "ABI %u, header %u",
           aobake_rt_abi_version(), AOBAKE_RT_ABI_VERSION);
    EXPECT(strlen(aobake_rt_version()) > 0, "no version");
    size_t len;
    uint8_t *bytes = slurp(argv[2], &len);
    size_t n;
    float *receivers = numbers(argv[4], &n);
    EXPECT(n % 8 == 0 && n > 0, "POINTS: 8 numbers a line");
    size_t count = n / 8;
    float *points = malloc(3 * count * sizeof *points);
    float *normals = malloc(3 * count * sizeof *normals);
    int64_t *parts = malloc(count * sizeof *parts);
    int64_t *kinds = malloc(count * sizeof *kinds);
    for (size_t i = 0; i < count; i++) {
        memcpy(points + 3 * i, receivers + 8 * i, 3 * sizeof *points);
        memcpy(normals + 3 * i, receivers + 8 * i + 3, 3 * sizeof *normals);
        parts[i] = (int64_t)receivers[8 * i + 6];
        kinds[i] = (int64_t)receivers[8 * i + 7];
    }
    float *out = malloc(2 * count * sizeof *out);
    FILE *f = fopen(argv[5], "wb");
    EXPECT(f, "cannot write %s", argv[5]);

    if (strcmp(argv[1], "cubemap") == 0) {
        EXPECT(aobake_grid_open(bytes, len) == NULL, "a cubemap opened as a grid");
        EXPECT(strstr(aobake_last_error(), "grid"), "cubemap as grid: %s", aobake_last_error());
        AobakeCubemap *c = aobake_cubemap_open(bytes, len);
        EXPECT(c, "open: %s", aobake_last_error());
        EXPECT(aobake_cubemap_duration(c) > 0.0f, "no duration");
        EXPECT(aobake_cubemap_occlusion(c, strtof(argv[3], NULL), points, count, out),
               "%s", aobake_last_error());
        EXPECT(aobake_cubemap_ground_ao(c, strtof(argv[3], NULL), points, count, out + count),
               "%s", aobake_last_error());
        fwrite(out, sizeof *out, 2 * count, f);
        if (count > 0) {
            /* A NaN in the last point: refused, and nothing written. */
            float kept = points[3 * count - 2];
            points[3 * count - 2] = NAN;
            for (size_t i = 0; i < count; i++) out[i] = -7.0f;
            EXPECT(!aobake_cubemap_occlusion(c, 0.0f, points, count, out),
                   "a NaN point was taken");
            EXPECT(strstr(aobake_last_error(), "not finite"), "%s", aobake_last_error());
            for (size_t i = 0; i < count; i++) EXPECT(out[i] == -7.0f, "out[%zu] written", i);
            points[3 * count - 2] = kept;
        }
        AobakeCubemapGpuParams params;
        EXPECT(aobake_cubemap_gpu_params(c, &params), "%s", aobake_last_error());
        fwrite(&params, sizeof params, 1, f);
        float phase = aobake_cubemap_phase(c, strtof(argv[3], NULL));
        fwrite(&phase, sizeof phase, 1, f);
        DUMP_WORDS(f, aobake_cubemap_gpu_words, c, AOBAKE_CUBEMAP_GPU_TEXELS);
        DUMP_WORDS(f, aobake_cubemap_gpu_words, c, AOBAKE_CUBEMAP_GPU_GROUND);
        aobake_cubemap_free(c);
    } else {
        EXPECT(aobake_cubemap_open(bytes, len) == NULL, "a grid opened as a cubemap");
        AobakeGrid *g = aobake_grid_open(bytes, len);
        EXPECT(g, "open: %s", aobake_last_error());
        size_t m;
        float *palette = numbers(argv[3], &m);
        EXPECT(m % 16 == 0 && m / 16 == aobake_grid_palette_len(g), "PALETTE: %zu numbers", m);
        EXPECT(aobake_grid_part_count(g) > 0, "no parts");
        EXPECT(!aobake_grid_occlusion(g, palette, m / 16 - 1, points, normals, parts, count, out),
               "a short palette was taken");
        EXPECT(aobake_grid_occlusion(g, palette, m / 16, points, normals, parts, count, out),
               "%s", aobake_last_error());
        if (count > 0) {
            /* A vertex past the character's (the last receiver): refused,
               not given offset 0, and nothing written. */
            int64_t kept = kinds[count - 1];
            kinds[count - 1] = (int64_t)1 << 40;
            for (size_t i = 0; i < count; i++) out[count + i] = -7.0f;
            EXPECT(!aobake_grid_ao(g, palette, m / 16, points, normals, parts, kinds, count, out + count),
                   "a vertex past the character was taken");
            EXPECT(strstr(aobake_last_error(), "vertex") != NULL, "%s", aobake_last_error());
            for (size_t i = 0; i < count; i++) EXPECT(out[count + i] == -7.0f, "out[%zu] written", i);
            kinds[count - 1] = kept;
        }
        EXPECT(aobake_grid_ao(g, palette, m / 16, points, normals, parts, kinds, count, out + count),
               "%s", aobake_last_error());
        fwrite(out, sizeof *out, 2 * count, f);
        if (count > 0) {
            /* A NaN normal, and a joint's matrix that cannot be inverted:
               refused with the reason, not NaN occlusion. */
            float kept = normals[0];
            normals[0] = NAN;
            EXPECT(!aobake_grid_occlusion(g, palette, m / 16, points, normals, parts, count, out),
                   "a NaN normal was taken");
            EXPECT(strstr(aobake_last_error(), "normals: item 0 is not finite"), "%s",
                   aobake_last_error());
            normals[0] = kept;
            size_t joint = (size_t)aobake_grid_part_joint(g, 0);
            float matrix[16];
            memcpy(matrix, palette + 16 * joint, sizeof matrix);
            memset(palette + 16 * joint, 0, sizeof matrix);
            EXPECT(!aobake_grid_occlusion(g, palette, m / 16, points, normals, parts, count, out),
                   "a singular matrix was taken");
            EXPECT(strstr(aobake_last_error(), "cannot be inverted"), "%s", aobake_last_error());
            memcpy(palette + 16 * joint, matrix, sizeof matrix);
        }
        AobakeGridGpuParams params;
        EXPECT(aobake_grid_gpu_params(g, &params), "%s", aobake_last_error());
        EXPECT(params.parts == aobake_grid_part_count(g), "%u parts", params.parts);
        fwrite(&params, sizeof params, 1, f);
        for (size_t k = 0; k < params.parts; k++) {
            int64_t joint = aobake_grid_part_joint(g, k);
            EXPECT(joint >= 0 && (size_t)joint < m / 16, "part %zu: joint %lld", k, (long long)joint);
            fwrite(&joint, sizeof joint, 1, f);
        }
        EXPECT(aobake_grid_part_joint(g, params.parts) == -1, "a part past the last");
        DUMP_WORDS(f, aobake_grid_gpu_words, g, AOBAKE_GRID_GPU_INFOS);
        DUMP_WORDS(f, aobake_grid_gpu_words, g, AOBAKE_GRID_GPU_CELLS);
        DUMP_WORDS(f, aobake_grid_gpu_words, g, AOBAKE_GRID_GPU_VERTEX_OFFSETS);
        DUMP_WORDS(f, aobake_grid_gpu_words, g, AOBAKE_GRID_GPU_GROUND);
        float *poses = malloc(32 * params.parts * sizeof *poses);
        EXPECT(!aobake_grid_gpu_poses(g, palette, m / 16, poses, 32 * params.parts - 1),
               "a short poses buffer was taken");
        EXPECT(aobake_grid_gpu_poses(g, palette, m / 16, poses, 32 * params.parts),
               "%s", aobake_last_error());
        fwrite(poses, sizeof *poses, 32 * params.parts, f);
        free(poses);
        free(palette);
        aobake_grid_free(g);
    }
    fclose(f);
    printf("%zu receivers\n", count);
    free(bytes); free(receivers); free(points); free(normals); free(parts); free(kinds); free(out);
    return 0;
}
