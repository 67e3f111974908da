#!/usr/bin/env python3
"""Evaluates the AO of a glTF file written by `aobake export --gltf` at a
pose, from the file alone, as an engine would: what docs/engines.md
describes, in plain Python (no packages), so that the tests can hold the
export to `aobake eval`.

    gltf_ao.py FILE.glb [--clip NAME --time SECONDS] > ao.csv

Prints `index,occlusion` per vertex in aobake's vertex order (the order of
`extras.aobake.primitives`), like `aobake eval`. Without --clip the nodes
keep the transforms the file gives them (the bind pose).

The pose: each animated node's local translation, rotation and scale,
sampled from the clip (STEP, LINEAR with slerp for rotations, CUBICSPLINE);
the other nodes keep theirs. The weights: the asset's per-pose step from
`extras.aobake` (`layout`, `sections`); the AO: per vertex
`clamp(sum_j w_j * row_j(v), 0, 1)` with the rows in `_AO_BASIS_k`.

A texel asset's export (`extras.aobake.family` "texel") holds the rows as
16-bit grey PNG images instead (`extras.aobake.basis`: image, offset,
scale); the AO of a vertex is then `clamp(sum_j w_j * basis_j(uv), 0, 1)`,
each basis filtered bilinearly at the UV (`TEXCOORD_<texcoord>`) of the
first exported vertex that is that vertex (`vertex_of`), as `aobake eval`
samples it. The PNGs are decoded here too (zlib and the five filters).
"""

import argparse
import json
import math
import struct
import sys
import zlib

F32 = struct.Struct("<f")


def f32(x):
    """x rounded to single precision."""
    return F32.unpack(F32.pack(x))[0]


COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
FORMATS = {5120: "b", 5121: "B", 5122: "h", 5123: "H", 5125: "I", 5126: "f"}
NORMALISE = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}


def read_glb(path):
    data = open(path, "rb").read()
    magic, _version, _length = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF":
        sys.exit(f"{path}: not a GLB")
    at, gltf, bin_chunk = 12, None, b""
    while at < len(data):
        size, kind = struct.unpack_from("<II", data, at)
        chunk = data[at + 8 : at + 8 + size]
        if kind == 0x4E4F534A:
            gltf = json.loads(chunk)
        elif kind == 0x004E4942:
            bin_chunk = chunk
        at += 8 + size
    return gltf, bin_chunk


def accessor(gltf, binary, index):
    """An accessor's elements as lists of floats (normalised integers scaled)."""
    a = gltf["accessors"][index]
    view = gltf["bufferViews"][a["bufferView"]]
    width = COMPONENTS[a["type"]]
    fmt = FORMATS[a["componentType"]]
    size = struct.calcsize(fmt)
    stride = view.get("byteStride", width * size)
    base = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    scale = NORMALISE.get(a["componentType"]) if a.get("normalized") else None
    out = []
    for i in range(a["count"]):
        values = struct.unpack_from("<" + fmt * width, binary, base + i * stride)
        if scale:
            values = tuple(max(v / scale, -1.0) for v in values)
        out.append(list(values))
    return out


# Quaternions are [x, y, z, w].
def q_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return [
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ]


def q_inv(q):
    x, y, z, w = q
    n = x * x + y * y + z * z + w * w
    return [-x / n, -y / n, -z / n, w / n]


def q_norm(q):
    n = math.sqrt(sum(c * c for c in q))
    return [c / n for c in q]


def q_rotate(q, v):
    p = q_mul(q_mul(q, [v[0], v[1], v[2], 0.0]), q_inv(q))
    return p[:3]


def acos_approx(v):
    """acos as glam (aobake's maths library) computes it in slerp: DirectXMath's
    7-degree minimax polynomial. Exact acos differs by up to about 1e-5 rad,
    which the standardised joint angles can turn into 1e-5 of AO."""
    x = abs(v)
    root = math.sqrt(max(1.0 - x, 0.0))
    r = ((((((-0.0012624911 * x + 0.00667009) * x - 0.017088126) * x + 0.03089188) * x
           - 0.050174303) * x + 0.08897899) * x - 0.2145988) * x + 1.5707963
    r *= root
    return r if v >= 0.0 else math.pi - r


def slerp(a, b, s):
    """glam's slerp: the short arc, lerp when the keys all but coincide."""
    dot = sum(x * y for x, y in zip(a, b))
    if dot < 0.0:
        b, dot = [-c for c in b], -dot
    if dot > 1.0 - 1.1920929e-07:
        return q_norm([x * (1.0 - s) + y * s for x, y in zip(a, b)])
    theta = acos_approx(dot)
    sa, sb, st = math.sin(theta * (1 - s)), math.sin(theta * s), math.sin(theta)
    return [(x * sa + y * sb) / st for x, y in zip(a, b)]


def rotation_vector(q):
    """log(q) as axis times angle, angle in [0, pi]."""
    if q[3] < 0.0:
        q = [-c for c in q]
    length = math.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2)
    if length < 1e-8:
        return [0.0, 0.0, 0.0]
    angle = 2.0 * math.atan2(length, q[3])
    return [c / length * angle for c in q[:3]]


def rotation_matrix_minus_identity(r):
    """R(r) - I, column-major, for a rotation vector r."""
    angle = math.sqrt(sum(c * c for c in r))
    if angle > 0.0:
        axis = [c / angle for c in r]
        h = 0.5 * angle
        q = [axis[0] * math.sin(h), axis[1] * math.sin(h), axis[2] * math.sin(h), math.cos(h)]
    else:
        q = [0.0, 0.0, 0.0, 1.0]
    cols = [q_rotate(q, e) for e in ([1, 0, 0], [0, 1, 0], [0, 0, 1])]
    return [cols[c][r_] - (1.0 if c == r_ else 0.0) for c in range(3) for r_ in range(3)]


class Transform:
    def __init__(self, t=(0, 0, 0), r=(0, 0, 0, 1), s=(1, 1, 1)):
        self.t, self.r, self.s = list(t), list(r), list(s)

    def apply(self, p):
        """parent_from_local: T R S p."""
        scaled = [p[i] * self.s[i] for i in range(3)]
        rotated = q_rotate(self.r, scaled)
        return [rotated[i] + self.t[i] for i in range(3)]


def decompose(m):
    """A column-major TRS matrix as translation, rotation, scale."""
    cols = [m[0:3], m[4:7], m[8:11]]
    scale = [math.sqrt(sum(c * c for c in col)) for col in cols]
    det = (cols[0][0] * (cols[1][1] * cols[2][2] - cols[2][1] * cols[1][2])
           - cols[1][0] * (cols[0][1] * cols[2][2] - cols[2][1] * cols[0][2])
           + cols[2][0] * (cols[0][1] * cols[1][2] - cols[1][1] * cols[0][2]))
    if det < 0:
        scale[0] = -scale[0]
    r = [[cols[c][row] / scale[c] for c in range(3)] for row in range(3)]
    trace = r[0][0] + r[1][1] + r[2][2]
    if trace > 0:
        t = math.sqrt(1.0 + trace) * 2
        q = [(r[2][1] - r[1][2]) / t, (r[0][2] - r[2][0]) / t, (r[1][0] - r[0][1]) / t, 0.25 * t]
    elif r[0][0] > r[1][1] and r[0][0] > r[2][2]:
        t = math.sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]) * 2
        q = [0.25 * t, (r[0][1] + r[1][0]) / t, (r[0][2] + r[2][0]) / t, (r[2][1] - r[1][2]) / t]
    elif r[1][1] > r[2][2]:
        t = math.sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]) * 2
        q = [(r[0][1] + r[1][0]) / t, 0.25 * t, (r[1][2] + r[2][1]) / t, (r[0][2] - r[2][0]) / t]
    else:
        t = math.sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]) * 2
        q = [(r[0][2] + r[2][0]) / t, (r[1][2] + r[2][1]) / t, 0.25 * t, (r[1][0] - r[0][1]) / t]
    return m[12:15], q_norm(q), scale


def rest_transforms(gltf):
    out = []
    for node in gltf.get("nodes", []):
        if "matrix" in node:
            t, r, s = decompose(node["matrix"])
            out.append(Transform(t, r, s))
            continue
        # As the file's reader holds them: single-precision floats, the
        # rotation normalised.
        single = lambda v: [f32(c) for c in v]
        rotation = single(q_norm(single(node.get("rotation", (0, 0, 0, 1)))))
        out.append(Transform(single(node.get("translation", (0, 0, 0))), rotation, single(node.get("scale", (1, 1, 1)))))
    return out


def sample(gltf, binary, clip, time, locals_):
    for channel in clip["channels"]:
        target = channel["target"]
        if "node" not in target or target["path"] == "weights":
            continue
        sampler = clip["samplers"][channel["sampler"]]
        times = [t[0] for t in accessor(gltf, binary, sampler["input"])]
        values = accessor(gltf, binary, sampler["output"])
        mode = sampler.get("interpolation", "LINEAR")
        cubic = mode == "CUBICSPLINE"
        value = lambda k: values[3 * k + 1] if cubic else values[k]
        n = len(times)
        nxt = next((i for i, t in enumerate(times) if t > time), n)
        path = target["path"]
        if nxt == 0:
            out = value(0)
        elif nxt >= n:
            out = value(n - 1)
        else:
            k = nxt - 1
            t0, t1 = times[k], times[nxt]
            dt = t1 - t0
            if dt <= 0.0 or mode == "STEP":
                out = value(k)
            else:
                s = (time - t0) / dt
                if mode == "LINEAR" and path == "rotation":
                    out = slerp(value(k), value(nxt), s)
                elif mode == "LINEAR":
                    out = [a + (b - a) * s for a, b in zip(value(k), value(nxt))]
                else:
                    s2, s3 = s * s, s * s * s
                    h00, h10 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s
                    h01, h11 = -2 * s3 + 3 * s2, s3 - s2
                    v0, b0 = values[3 * k + 1], values[3 * k + 2]
                    a1, v1 = values[3 * nxt], values[3 * nxt + 1]
                    out = [h00 * v0[i] + h10 * dt * b0[i] + h01 * v1[i] + h11 * dt * a1[i] for i in range(len(v0))]
        node = locals_[target["node"]]
        if path == "rotation":
            node.r = [f32(c) for c in q_norm(out)]
        elif path == "translation":
            node.t = list(out)
        elif path == "scale":
            node.s = list(out)


def parents(gltf):
    out = [None] * len(gltf.get("nodes", []))
    for i, node in enumerate(gltf.get("nodes", [])):
        for c in node.get("children", []):
            out[c] = i
    return out


def world_point(chain, p):
    """Applies a node's chain of local transforms (node first, root last)."""
    for t in chain:
        p = t.apply(p)
    return p


def chain_of(node, parent, locals_):
    out = []
    while node is not None:
        out.append(locals_[node])
        node = parent[node]
    return out


def inverse_apply(chain, p):
    """world -> node frame: undo each transform from the root down."""
    for t in reversed(chain):
        d = [p[i] - t.t[i] for i in range(3)]
        d = q_rotate(q_inv(t.r), d)
        p = [d[i] / t.s[i] for i in range(3)]
    return p


def joint_angles(layout, rest, locals_):
    out = []
    for j in layout["joints"]:
        conjugate = [-rest[j].r[0], -rest[j].r[1], -rest[j].r[2], rest[j].r[3]]
        out.extend(rotation_vector(q_mul(conjugate, locals_[j].r)))
    for t in layout["translations"]:
        out.extend(locals_[t].t[i] - rest[t].t[i] for i in range(3))
    for t in layout.get("scales", []):
        out.extend(locals_[t].s[i] / rest[t].s[i] - 1.0 if rest[t].s[i] != 0 else 0.0 for i in range(3))
    return out


def linear_weights(angles, ranges, rotations, features, components, norm, proj):
    clamped = [min(max(a, r["min"]), r["max"]) for a, r in zip(angles, ranges)]
    if features == "matrix":
        f = []
        for j in range(rotations):
            f.extend(rotation_matrix_minus_identity(clamped[3 * j : 3 * j + 3]))
        f.extend(clamped[3 * rotations :])
    else:
        f = clamped
    n = len(f)
    mean, inv_std = norm[:n], norm[n:]
    z = [(x - m) * s for x, m, s in zip(f, mean, inv_std)]
    if components:
        z = [sum(proj[c * n + i] * z[i] for i in range(n)) for c in range(components)]
    return z + [1.0]


def apply_basis(w, bmix, rank):
    inputs = len(w)
    mix, offset = bmix[: inputs * rank], bmix[inputs * rank :]
    out = [-o for o in offset]
    for i, wi in enumerate(w):
        if wi != 0.0:
            for r in range(rank):
                out[r] += wi * mix[i * rank + r]
    return out + [1.0]


def handles(layout, parent, locals_):
    root = layout["root"]
    out = []
    for j, offset in zip(layout["joints"], layout["offsets"]):
        chain = chain_of(j, parent, locals_)
        for p in ([0.0, 0.0, 0.0], offset):
            world = world_point(chain, p)
            out.extend(inverse_apply(chain_of(root, parent, locals_), world) if root is not None else world)
    return out


def clustered_weights(layout, sections, h, angles):
    n, alpha, clamp = layout["dimensions"], layout["alpha"], layout["clamp"]
    m, hl = len(layout["columns"]), len(h)
    centres, axes = sections["CENT"], sections["AXES"]
    d2 = [sum((h[i] - centres[j * hl + i]) ** 2 for i in range(hl)) for j in range(m)]
    if 0.0 in d2:
        omega = [1.0 if j == d2.index(0.0) else 0.0 for j in range(m)]
    else:
        logs = [-0.5 * alpha * math.log(d) for d in d2]
        top = max(logs)
        omega = [math.exp(l - top) for l in logs]
        total = sum(omega)
        omega = [w / total for w in omega]
        omega = [0.0 if w < 1e-4 else w for w in omega]
        total = sum(omega)
        omega = [w / total for w in omega]
    base = layout.get("base")
    if base:
        ja = base["joint_angles"]
        out = linear_weights(angles, ja["ranges"], len(ja["joints"]), base["features"], base["components"], sections["BNRM"], sections.get("BPRJ"))
    else:
        out = [1.0]
    for j in range(m):
        for r in range(n):
            axis = axes[(j * n + r) * hl : (j * n + r + 1) * hl]
            y = sum(a * (h[i] - centres[j * hl + i]) for i, a in enumerate(axis))
            if clamp > 0.0:
                y = min(max(y, -clamp), clamp)
            out.append(omega[j] * y)
        if layout["centering"] == "cluster":
            out.append(omega[j])
    return out


def weights(meta, gltf, locals_, rest):
    layout, sections = meta["layout"], meta["sections"]
    kind = layout["kind"]
    if kind == "static-average":
        return [1.0]
    if kind == "vertex-linear":
        ja = layout["joint_angles"]
        w = linear_weights(joint_angles(ja, rest, locals_), ja["ranges"], len(ja["joints"]), layout.get("features", "rotation-vector"), layout.get("components", 0), sections["NORM"], sections.get("PROJ"))
    else:
        parent = parents(gltf)
        h = handles(layout["handles"], parent, locals_)
        base = layout.get("base")
        angles = joint_angles(base["joint_angles"], rest, locals_) if base else []
        w = clustered_weights(layout, sections, h, angles)
    if layout.get("basis", 0):
        w = apply_basis(w, sections["BMIX"], layout["basis"])
    return w


def png_grey(data):
    """A non-interlaced grey PNG (8 or 16 bits): width, height, samples."""
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        sys.exit("an image is not a PNG")
    at, idat, header = 8, b"", None
    while at < len(data):
        length, kind = struct.unpack_from(">I4s", data, at)
        body = data[at + 8 : at + 8 + length]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        at += 12 + length
    width, height, depth, colour, _compression, _filter, interlace = header
    if colour != 0 or interlace != 0 or depth not in (8, 16):
        sys.exit("an image is not a plain grey PNG")
    bpp = depth // 8
    stride = width * bpp
    raw = zlib.decompress(idat)
    prev = bytearray(stride)
    samples = []
    for y in range(height):
        kind = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1 : (y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if kind == 1:
                line[i] = (line[i] + a) & 255
            elif kind == 2:
                line[i] = (line[i] + b) & 255
            elif kind == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif kind == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        samples.extend(struct.unpack(f">{width}H", line) if depth == 16 else line)
        prev = line
    return width, height, samples


def image(gltf, binary, index):
    view = gltf["bufferViews"][gltf["images"][index]["bufferView"]]
    at = view.get("byteOffset", 0)
    return png_grey(binary[at : at + view["byteLength"]])


def bilinear(values, width, height, u, v):
    """A linear sampler's filtering, clamped to the edge (centres at halves)."""
    x, y = u * width - 0.5, v * height - 0.5
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0

    def at(xi, yi):
        return values[min(max(yi, 0), height - 1) * width + min(max(xi, 0), width - 1)]

    top = at(x0, y0) * (1 - fx) + at(x0 + 1, y0) * fx
    bottom = at(x0, y0 + 1) * (1 - fx) + at(x0 + 1, y0 + 1) * fx
    return top * (1 - fy) + bottom * fy


def texel_ao(meta, gltf, binary, w):
    """Per vertex of aobake's order: the texel textures at its UV."""
    width, height = meta["atlas"]["width"], meta["atlas"]["height"]
    basis = []
    for layer in meta["basis"]:
        w_, h_, samples = image(gltf, binary, layer["image"])
        if (w_, h_) != (width, height):
            sys.exit(f"a basis image is {w_} x {h_}, the atlas {width} x {height}")
        basis.append([layer["offset"] + layer["scale"] * q / 65535.0 for q in samples])
    out = {}
    for p in meta["primitives"]:
        attributes = gltf["meshes"][p["mesh"]]["primitives"][p["primitive"]]["attributes"]
        uvs = accessor(gltf, binary, attributes[f"TEXCOORD_{p['texcoord']}"])
        vertex_of = accessor(gltf, binary, p["vertex_of"])
        for (x,), (u, v) in zip(vertex_of, uvs):
            if x not in out:
                ao = sum(wj * bilinear(b, width, height, u, v) for wj, b in zip(w, basis))
                out[x] = min(max(ao, 0.0), 1.0)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("file")
    parser.add_argument("--clip")
    parser.add_argument("--time", type=float, default=0.0)
    args = parser.parse_args()
    gltf, binary = read_glb(args.file)
    meta = gltf["extras"]["aobake"]
    rest = rest_transforms(gltf)
    locals_ = [Transform(t.t, t.r, t.s) for t in rest]
    if args.clip is not None:
        clips = [a for i, a in enumerate(gltf.get("animations", [])) if (a.get("name") or f"animation_{i}") == args.clip]
        if not clips:
            sys.exit(f"no animation named {args.clip!r}")
        sample(gltf, binary, clips[0], f32(args.time), locals_)
    # The weights as an engine uploads them: single precision.
    w = [f32(x) for x in weights(meta, gltf, locals_, rest)]
    print("index,occlusion")
    if meta.get("family") == "texel":
        ao = texel_ao(meta, gltf, binary, w)
        for x in range(meta["vertices"]):
            print(f"{x},{ao.get(x, 0.0)!r}")
        return
    for p in meta["primitives"]:
        attributes = gltf["meshes"][p["mesh"]]["primitives"][p["primitive"]]["attributes"]
        if meta["basis"]:
            rows = [accessor(gltf, binary, attributes[name]) for name in meta["basis"]]
            for i in range(p["count"]):
                coefficients = [c for attr in rows for c in attr[i]][: len(w)]
                # Row by row in single precision, as the run time sums.
                ao = 0.0
                for wj, cj in zip(w, coefficients):
                    if wj != 0.0:
                        ao = f32(ao + f32(wj * cj))
                print(f"{p['first'] + i},{min(max(ao, 0.0), 1.0)!r}")
        else:
            static = accessor(gltf, binary, attributes[meta["static"]["attribute"]])
            for i in range(p["count"]):
                print(f"{p['first'] + i},{static[i][0]!r}")


if __name__ == "__main__":
    main()
