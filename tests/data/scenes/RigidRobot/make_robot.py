#!/usr/bin/env python3
"""Writes RigidRobot.gltf: an 11-part rigid robot (Malmer et al.'s test
object has 11 parts) with two clips, Walk and Reach. Every part is a mesh
node (a box cut into 3 x 3 quads a face, flat normals) hung on its parent
at its joint, so the animation moves the parts rigidly. Run it from this
directory; the output is deterministic."""
import base64, json, math, struct

SUB = 3  # quads per box edge

def box(size, offset):
    """A box of `size` whose centre is `offset` from the node's origin."""
    sx, sy, sz = (s / 2 for s in size)
    pos, nor, idx = [], [], []
    faces = [  # normal, u axis, v axis (u x v = normal)
        ((1, 0, 0), (0, 0, -1), (0, 1, 0)), ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
        ((0, 1, 0), (1, 0, 0), (0, 0, -1)), ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
        ((0, 0, 1), (1, 0, 0), (0, 1, 0)), ((0, 0, -1), (-1, 0, 0), (0, 1, 0)),
    ]
    half = (sx, sy, sz)
    for n, u, v in faces:
        base = len(pos)
        for j in range(SUB + 1):
            for i in range(SUB + 1):
                a, b = -1 + 2 * i / SUB, -1 + 2 * j / SUB
                p = [offset[k] + half[k] * (n[k] + a * u[k] + b * v[k]) for k in range(3)]
                pos.append(p)
                nor.append(list(n))
        for j in range(SUB):
            for i in range(SUB):
                q = base + j * (SUB + 1) + i
                idx += [q, q + 1, q + SUB + 2, q, q + SUB + 2, q + SUB + 1]
    return pos, nor, idx

# name, parent, joint position relative to parent, box size, box centre from joint
PARTS = [
    ("Pelvis", None, (0, 0.95, 0), (0.34, 0.16, 0.2), (0, 0, 0)),
    ("Torso", "Pelvis", (0, 0.1, 0), (0.42, 0.5, 0.24), (0, 0.27, 0)),
    ("Head", "Torso", (0, 0.56, 0), (0.22, 0.24, 0.22), (0, 0.14, 0)),
    ("UpperArmL", "Torso", (0.28, 0.48, 0), (0.1, 0.3, 0.1), (0, -0.15, 0)),
    ("ForearmL", "UpperArmL", (0, -0.32, 0), (0.09, 0.3, 0.09), (0, -0.15, 0)),
    ("UpperArmR", "Torso", (-0.28, 0.48, 0), (0.1, 0.3, 0.1), (0, -0.15, 0)),
    ("ForearmR", "UpperArmR", (0, -0.32, 0), (0.09, 0.3, 0.09), (0, -0.15, 0)),
    ("ThighL", "Pelvis", (0.1, -0.08, 0), (0.13, 0.4, 0.13), (0, -0.2, 0)),
    ("ShinL", "ThighL", (0, -0.42, 0), (0.11, 0.4, 0.11), (0, -0.2, 0.0)),
    ("ThighR", "Pelvis", (-0.1, -0.08, 0), (0.13, 0.4, 0.13), (0, -0.2, 0)),
    ("ShinR", "ThighR", (0, -0.42, 0), (0.11, 0.4, 0.11), (0, -0.2, 0.0)),
]

def quat_x(deg):
    a = math.radians(deg) / 2
    return [math.sin(a), 0.0, 0.0, math.cos(a)]

def quat_z(deg):
    a = math.radians(deg) / 2
    return [0.0, 0.0, math.sin(a), math.cos(a)]

def walk(name, t):  # t in [0, 1)
    s = math.sin(2 * math.pi * t)
    c = math.cos(2 * math.pi * t)
    return {
        "ThighL": quat_x(-30 * s), "ThighR": quat_x(30 * s),
        "ShinL": quat_x(35 + 35 * c), "ShinR": quat_x(35 - 35 * c),
        "UpperArmL": quat_x(35 * s), "UpperArmR": quat_x(-35 * s),
        "ForearmL": quat_x(-30 - 20 * s), "ForearmR": quat_x(-30 + 20 * s),
        "Torso": quat_x(4 + 2 * c), "Head": quat_x(-4 * s),
    }.get(name)

def reach(name, t):  # arms forward and up, bending down and back
    s = 0.5 - 0.5 * math.cos(2 * math.pi * t)  # 0 -> 1 -> 0
    return {
        "UpperArmL": quat_x(-150 * s), "UpperArmR": quat_x(-150 * s),
        "ForearmL": quat_x(-40 * s), "ForearmR": quat_x(-40 * s),
        "Torso": quat_x(40 * s), "Head": quat_x(-20 * s),
        "ThighL": quat_x(-50 * s), "ThighR": quat_x(-50 * s),
        "ShinL": quat_x(90 * s), "ShinR": quat_x(90 * s),
    }.get(name)

blob = bytearray()
accessors, views = [], []

def add(data, fmt, comps, target=None, minmax=False, kind=5126):
    global blob
    while len(blob) % 4:
        blob.append(0)
    offset = len(blob)
    for row in data:
        blob += struct.pack("<" + fmt * comps, *(row if comps > 1 else [row]))
    view = {"buffer": 0, "byteOffset": offset, "byteLength": len(blob) - offset}
    if target:
        view["target"] = target
    views.append(view)
    acc = {"bufferView": len(views) - 1, "componentType": kind, "count": len(data),
           "type": {1: "SCALAR", 3: "VEC3", 4: "VEC4"}[comps]}
    if minmax:
        cols = list(zip(*data)) if comps > 1 else [data]
        acc["min"] = [min(c) for c in cols]
        acc["max"] = [max(c) for c in cols]
    accessors.append(acc)
    return len(accessors) - 1

nodes, meshes = [], []
index = {name: i for i, (name, *_rest) in enumerate(PARTS)}
for name, parent, joint, size, centre in PARTS:
    pos, nor, idx = box(size, centre)
    p = add(pos, "f", 3, 34962, True)
    n = add(nor, "f", 3, 34962)
    i = add(idx, "H", 1, 34963, kind=5123)
    meshes.append({"name": name, "primitives": [{"attributes": {"POSITION": p, "NORMAL": n}, "indices": i}]})
    nodes.append({"name": name, "mesh": len(meshes) - 1, "translation": list(joint)})
for name, parent, *_ in PARTS:
    if parent:
        nodes[index[parent]].setdefault("children", []).append(index[name])

animations = []
for clip, fn, duration in [("Walk", walk, 1.6), ("Reach", reach, 2.4)]:
    frames = 24
    times = [duration * k / frames for k in range(frames + 1)]
    t_acc = add(times, "f", 1, minmax=True)
    channels, samplers = [], []
    for name, *_ in PARTS:
        if fn(name, 0.0) is None:
            continue
        q = add([fn(name, k / frames) for k in range(frames + 1)], "f", 4)
        samplers.append({"input": t_acc, "output": q, "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": index[name], "path": "rotation"}})
    if clip == "Walk":  # the pelvis bobs twice a cycle
        y = [[0, 0.95 + 0.025 * math.cos(4 * math.pi * k / frames), 0] for k in range(frames + 1)]
        samplers.append({"input": t_acc, "output": add(y, "f", 3), "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": 0, "path": "translation"}})
    if clip == "Reach":  # the pelvis drops as the knees bend
        y = [[0, 0.95 - 0.2 * (0.5 - 0.5 * math.cos(2 * math.pi * k / frames)), 0.05 * (0.5 - 0.5 * math.cos(2 * math.pi * k / frames))] for k in range(frames + 1)]
        samplers.append({"input": t_acc, "output": add(y, "f", 3), "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": 0, "path": "translation"}})
    animations.append({"name": clip, "channels": channels, "samplers": samplers})

doc = {
    "asset": {"version": "2.0", "generator": "aobake make_robot.py",
              "copyright": "CC0 1.0, made for aobake's tests"},
    "scene": 0, "scenes": [{"nodes": [0]}], "nodes": nodes, "meshes": meshes,
    "animations": animations, "accessors": accessors, "bufferViews": views,
    "buffers": [{"byteLength": len(blob),
                 "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode()}],
}
with open("RigidRobot.gltf", "w") as f:
    json.dump(doc, f, separators=(",", ":"))
    f.write("\n")
