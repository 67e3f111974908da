#!/usr/bin/env python3
"""Writes tests/data/props/Crates/Crates.glb: a static prop (no skin, no
animation) for the static bakes' tests. A 4 x 4 floor quad with three
boxes on it, one stacked on another; flat normals, indexed triangles, one
buffer. Vertices 0-3 are the floor, 4-27 the big box (top, bottom, +z,
-z, +x, -x faces, four each), then the small box and the stacked one.
CC0-1.0. Run from the repository's root."""
import json
import struct

pos, nrm, idx = [], [], []


def quad(a, b, c, d, n):
    base = len(pos)
    for p in (a, b, c, d):
        pos.append(p)
        nrm.append(n)
    idx.extend([base, base + 1, base + 2, base, base + 2, base + 3])


def box(cx, cy, cz, sx, sy, sz):
    x0, x1 = cx - sx / 2, cx + sx / 2
    y0, y1 = cy, cy + sy
    z0, z1 = cz - sz / 2, cz + sz / 2
    quad((x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0), (0, 1, 0))
    quad((x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1), (0, -1, 0))
    quad((x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1), (0, 0, 1))
    quad((x1, y0, z0), (x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (0, 0, -1))
    quad((x1, y0, z1), (x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (1, 0, 0))
    quad((x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0), (-1, 0, 0))


quad((-2, 0, -2), (-2, 0, 2), (2, 0, 2), (2, 0, -2), (0, 1, 0))
box(0, 0, 0, 1, 1, 1)
box(0.85, 0, 0.2, 0.6, 0.6, 0.6)
box(0.1, 1, -0.05, 0.5, 0.5, 0.5)

pb = b"".join(struct.pack("<3f", *p) for p in pos)
nb = b"".join(struct.pack("<3f", *n) for n in nrm)
ib = b"".join(struct.pack("<H", i) for i in idx)
while len(ib) % 4:
    ib += b"\0"
buf = pb + nb + ib
lo = [min(p[k] for p in pos) for k in range(3)]
hi = [max(p[k] for p in pos) for k in range(3)]
gltf = {
    "asset": {"version": "2.0", "generator": "aobake tests/data/props/Crates (made by hand, CC0)"},
    "scene": 0,
    "scenes": [{"name": "Crates", "nodes": [0]}],
    "nodes": [{"name": "Crates", "mesh": 0}],
    "meshes": [{"name": "Crates", "primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2}]}],
    "buffers": [{"byteLength": len(buf)}],
    "bufferViews": [
        {"buffer": 0, "byteOffset": 0, "byteLength": len(pb), "target": 34962},
        {"buffer": 0, "byteOffset": len(pb), "byteLength": len(nb), "target": 34962},
        {"buffer": 0, "byteOffset": len(pb) + len(nb), "byteLength": len(idx) * 2, "target": 34963},
    ],
    "accessors": [
        {"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3", "min": lo, "max": hi},
        {"bufferView": 1, "componentType": 5126, "count": len(nrm), "type": "VEC3"},
        {"bufferView": 2, "componentType": 5123, "count": len(idx), "type": "SCALAR"},
    ],
}
j = json.dumps(gltf, separators=(",", ":")).encode()
while len(j) % 4:
    j += b" "
glb = (
    b"glTF"
    + struct.pack("<II", 2, 12 + 8 + len(j) + 8 + len(buf))
    + struct.pack("<I", len(j))
    + b"JSON"
    + j
    + struct.pack("<I", len(buf))
    + b"BIN\0"
    + buf
)
with open("tests/data/props/Crates/Crates.glb", "wb") as f:
    f.write(glb)
