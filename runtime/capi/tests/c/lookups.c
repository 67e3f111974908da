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
 * (aobake_grid_ao). Also checks that the other kind of asset and a short
 * palette are refused with a reason. Exits non-zero on anything unexpected. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "aobake_rt.h"

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

int main(int argc, char **argv) {
    EXPECT(argc == 6, "usage: lookups cubemap|grid ASSET SECONDS|PALETTE POINTS OUT");
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
    size_t written = count;
    float *out = malloc(2 * count * sizeof *out);

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
        written = 2 * count;
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
            /* A vertex past the character's: refused, not given offset 0. */
            int64_t kept = kinds[0];
            kinds[0] = (int64_t)1 << 40;
            EXPECT(!aobake_grid_ao(g, palette, m / 16, points, normals, parts, kinds, count, out + count),
                   "a vertex past the character was taken");
            EXPECT(strstr(aobake_last_error(), "vertex") != NULL, "%s", aobake_last_error());
            kinds[0] = kept;
        }
        EXPECT(aobake_grid_ao(g, palette, m / 16, points, normals, parts, kinds, count, out + count),
               "%s", aobake_last_error());
        written = 2 * count;
        free(palette);
        aobake_grid_free(g);
    }
    FILE *f = fopen(argv[5], "wb");
    EXPECT(f, "cannot write %s", argv[5]);
    fwrite(out, sizeof *out, written, f);
    fclose(f);
    printf("%zu receivers\n", count);
    free(bytes); free(receivers); free(points); free(normals); free(parts); free(kinds); free(out);
    return 0;
}
