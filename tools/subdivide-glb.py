#!/usr/bin/env python3
"""Subdivide every triangle of a skinned glTF binary into four, LEVELS times:
a denser character with the same skeleton, skin and clips, for measuring
how a bake scales with vertices (issue 50: "a 40,000-vertex character
bakes within the same memory").

    python3 tools/subdivide-glb.py IN.glb OUT.glb [LEVELS]

Each edge gets one new vertex at its midpoint, shared by the triangles on
both sides (vertices split in the file, for UV seams, stay split). Its
attributes are the two ends' means: position, normal (renormalised),
texture coordinates; skin influences are the two ends' weights halved and
summed per joint, the four largest kept and renormalised. Pure Python
(no numpy): CesiumMan at two levels (about 40,000 vertices) takes a few
seconds. The new attributes and indices are appended to the binary chunk;
the old ones stay, unused.
"""

import json
import math
import struct
import sys

COMPONENT = {5120: "b", 5121: "B", 5122: "h", 5123: "H", 5125: "I", 5126: "f"}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def read_glb(path):
    data = open(path, "rb").read()
    magic, _, _ = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67, "not a glTF binary"
    length, kind = struct.unpack_from("<II", data, 12)
    assert kind == 0x4E4F534A
    doc = json.loads(data[20 : 20 + length])
    offset = 20 + length
    length, kind = struct.unpack_from("<II", data, offset)
    assert kind == 0x004E4942
    return doc, bytearray(data[offset + 8 : offset + 8 + length])


def read_accessor(doc, bin_, index):
    a = doc["accessors"][index]
    view = doc["bufferViews"][a["bufferView"]]
    fmt = COMPONENT[a["componentType"]]
    n = WIDTH[a["type"]]
    size = struct.calcsize("<" + fmt)
    stride = view.get("byteStride", size * n)
    base = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    out = []
    for i in range(a["count"]):
        values = struct.unpack_from("<" + fmt * n, bin_, base + i * stride)
        out.append(values if n > 1 else values[0])
    return out


def append(doc, bin_, values, component, kind, target=None):
    """Appends values as a new accessor; returns its index."""
    while len(bin_) % 4:
        bin_.append(0)
    fmt = COMPONENT[component]
    n = WIDTH[kind]
    start = len(bin_)
    flat = [x for v in values for x in (v if n > 1 else (v,))]
    bin_.extend(struct.pack("<" + fmt * len(flat), *flat))
    view = {"buffer": 0, "byteOffset": start, "byteLength": len(bin_) - start}
    if target:
        view["target"] = target
    doc["bufferViews"].append(view)
    accessor = {
        "bufferView": len(doc["bufferViews"]) - 1,
        "componentType": component,
        "count": len(values),
        "type": kind,
    }
    if kind == "VEC3" and component == 5126:
        accessor["min"] = [min(v[k] for v in values) for k in range(3)]
        accessor["max"] = [max(v[k] for v in values) for k in range(3)]
    doc["accessors"].append(accessor)
    return len(doc["accessors"]) - 1


def midpoint(attrs, a, b):
    out = {}
    for name, values in attrs.items():
        x, y = values[a], values[b]
        if name.startswith("JOINTS_"):
            continue
        if name.startswith("WEIGHTS_"):
            joints = attrs["JOINTS_" + name[len("WEIGHTS_") :]]
            total = {}
            for j, w in list(zip(joints[a], x)) + list(zip(joints[b], y)):
                total[j] = total.get(j, 0.0) + w / 2
            best = sorted(total.items(), key=lambda jw: (-jw[1], jw[0]))[:4]
            s = sum(w for _, w in best) or 1.0
            best += [(0, 0.0)] * (4 - len(best))
            out["JOINTS_" + name[len("WEIGHTS_") :]] = tuple(j for j, _ in best)
            out[name] = tuple(w / s for _, w in best)
            continue
        m = tuple((p + q) / 2 for p, q in zip(x, y))
        if name == "NORMAL":
            length = math.sqrt(sum(c * c for c in m)) or 1.0
            m = tuple(c / length for c in m)
        out[name] = m
    return out


def subdivide(attrs, triangles):
    edges = {}

    def mid(a, b):
        key = (min(a, b), max(a, b))
        if key not in edges:
            new = midpoint(attrs, a, b)
            for name, value in new.items():
                attrs[name].append(value)
            edges[key] = len(attrs["POSITION"]) - 1
        return edges[key]

    out = []
    for a, b, c in triangles:
        ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
        out += [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]
    return out


def main():
    src, dst = sys.argv[1], sys.argv[2]
    levels = int(sys.argv[3]) if len(sys.argv) > 3 else 2
    doc, bin_ = read_glb(src)
    for mesh in doc["meshes"]:
        for prim in mesh["primitives"]:
            assert prim.get("mode", 4) == 4, "triangles only"
            assert not prim.get("targets"), "no morph targets"
            attrs = {
                name: read_accessor(doc, bin_, i) for name, i in prim["attributes"].items()
            }
            flat = read_accessor(doc, bin_, prim["indices"])
            triangles = [tuple(flat[i : i + 3]) for i in range(0, len(flat), 3)]
            for _ in range(levels):
                triangles = subdivide(attrs, triangles)
            for name, values in attrs.items():
                old = doc["accessors"][prim["attributes"][name]]
                component = old["componentType"]
                if name.startswith("JOINTS_"):
                    component = 5123
                prim["attributes"][name] = append(
                    doc, bin_, values, component, old["type"], 34962
                )
            prim["indices"] = append(
                doc, bin_, [i for t in triangles for i in t], 5125, "SCALAR", 34963
            )
            print(
                f"{mesh.get('name', 'mesh')}: {len(attrs['POSITION'])} vertices, "
                f"{len(triangles)} triangles"
            )
    while len(bin_) % 4:
        bin_.append(0)
    doc["buffers"][0]["byteLength"] = len(bin_)
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(bin_)
    with open(dst, "wb") as f:
        f.write(struct.pack("<III", 0x46546C67, 2, total))
        f.write(struct.pack("<II", len(text), 0x4E4F534A) + text)
        f.write(struct.pack("<II", len(bin_), 0x004E4942) + bytes(bin_))


if __name__ == "__main__":
    main()
