//! A corpus of hostile and broken uploads, shared by core's import tests
//! and the service's: every one must be refused with a clear error (a 4xx
//! problem+json over HTTP), none may panic or read outside the upload.

use serde_json::{Value, json};

/// A named hostile upload.
#[derive(Debug, Clone)]
pub struct Case {
    /// What is wrong with it.
    pub name: String,
    /// The file.
    pub bytes: Vec<u8>,
}

/// A GLB's JSON and BIN chunks.
pub fn glb_parts(glb: &[u8]) -> (Value, Vec<u8>) {
    let u32_at = |i: usize| u32::from_le_bytes(glb[i..i + 4].try_into().unwrap()) as usize;
    let json_len = u32_at(12);
    let json: Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let bin_at = 20 + json_len;
    let bin = if bin_at + 8 <= glb.len() {
        let len = u32_at(bin_at);
        glb[bin_at + 8..bin_at + 8 + len].to_vec()
    } else {
        Vec::new()
    };
    (json, bin)
}

/// A GLB of this JSON and binary chunk.
pub fn glb(json: &Value, bin: &[u8]) -> Vec<u8> {
    let mut j = serde_json::to_vec(json).unwrap();
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    let total = 12 + 8 + j.len() + if b.is_empty() { 0 } else { 8 + b.len() };
    let mut out = Vec::with_capacity(total);
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((j.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(j);
    if !b.is_empty() {
        out.extend((b.len() as u32).to_le_bytes());
        out.extend(b"BIN\0");
        out.extend(b);
    }
    out
}

/// Removes an accessor's declared `min` and `max` (after an edit makes
/// them wrong, so that a case carries only the error it is about).
fn drop_bounds(accessor: &mut Value) {
    let map = accessor.as_object_mut().unwrap();
    map.remove("max");
    map.remove("min");
}

/// Where accessor `a`'s data starts in the binary chunk.
fn accessor_offset(json: &Value, a: usize) -> usize {
    let acc = &json["accessors"][a];
    let view = &json["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
    (view["byteOffset"].as_u64().unwrap_or(0) + acc["byteOffset"].as_u64().unwrap_or(0)) as usize
}

/// The corpus, built from a valid skinned, animated GLB (RiggedSimple).
pub fn corpus(valid: &[u8]) -> Vec<Case> {
    let mut out = Vec::new();
    let mut push = |name: &str, bytes: Vec<u8>| {
        out.push(Case {
            name: name.to_owned(),
            bytes,
        })
    };
    push("empty file", Vec::new());
    push("plain text", b"this is not a character".to_vec());
    push("a PNG", b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR".to_vec());
    let mut x = 0x9e37_79b9_7f4a_7c15u64;
    let noise: Vec<u8> = (0..4096)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect();
    push("random bytes", noise);
    for k in [1, 2, 3, 5, 8, 13, 21] {
        let len = valid.len() * k / 23;
        push(&format!("truncated to {len} bytes"), valid[..len].to_vec());
    }
    let mut lie = valid.to_vec();
    lie[8..12].copy_from_slice(&(valid.len() as u32 * 4).to_le_bytes());
    push("GLB length larger than the file", lie);
    push("deep JSON nesting", {
        let mut s = "[".repeat(100_000);
        s.push_str(&"]".repeat(100_000));
        s.into_bytes()
    });

    let (json, bin) = glb_parts(valid);
    let mut edit = |name: &str, f: &dyn Fn(&mut Value, &mut Vec<u8>)| {
        let (mut j, mut b) = (json.clone(), bin.clone());
        f(&mut j, &mut b);
        push(name, glb(&j, &b));
    };
    edit("asset.version 1.0", &|j, _| {
        j["asset"]["version"] = json!("1.0")
    });
    edit("asset.version 3.0", &|j, _| {
        j["asset"]["version"] = json!("3.0")
    });
    edit("unknown required extension", &|j, _| {
        j["extensionsUsed"] = json!(["ACME_teleport"]);
        j["extensionsRequired"] = json!(["ACME_teleport"]);
    });
    for uri in [
        "../../../../etc/passwd",
        "/etc/passwd",
        "file:///etc/passwd",
        "http://127.0.0.1:9/x.bin",
        "C:\\Windows\\win.ini",
    ] {
        edit(&format!("buffer URI {uri}"), &|j, _| {
            j["buffers"][0]["uri"] = json!(uri);
        });
    }
    edit("accessor count 2^31", &|j, _| {
        j["accessors"][0]["count"] = json!(1u64 << 31)
    });
    edit("node that is its own child", &|j, _| {
        j["nodes"][0]["children"] = json!([0]);
    });
    edit("skin joint that does not exist", &|j, _| {
        j["skins"][0]["joints"][0] = json!(999);
    });
    edit("animation target node that does not exist", &|j, _| {
        j["animations"][0]["channels"][0]["target"]["node"] = json!(999);
    });
    let position = json["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
        .as_u64()
        .unwrap() as usize;
    edit("NaN position", &|j, b| {
        let at = accessor_offset(j, position);
        b[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    });
    edit("infinite position", &|j, b| {
        let at = accessor_offset(j, position) + 4;
        b[at..at + 4].copy_from_slice(&f32::INFINITY.to_le_bytes());
    });
    if let Some(joints) = json["meshes"][0]["primitives"][0]["attributes"]["JOINTS_0"].as_u64() {
        edit("joint index outside the skin", &|j, b| {
            let at = accessor_offset(j, joints as usize);
            let wide = j["accessors"][joints as usize]["componentType"] == 5123;
            if wide {
                b[at..at + 2].copy_from_slice(&200u16.to_le_bytes());
            } else {
                b[at] = 200;
            }
        });
    }
    let input = json["animations"][0]["samplers"][0]["input"]
        .as_u64()
        .unwrap() as usize;
    edit("repeated key time", &|j, b| {
        let at = accessor_offset(j, input);
        let first: [u8; 4] = b[at..at + 4].try_into().unwrap();
        b[at + 4..at + 8].copy_from_slice(&first);
    });
    edit("key times going back", &|j, b| {
        let at = accessor_offset(j, input);
        b[at + 4..at + 8].copy_from_slice(&(-1.0f32).to_le_bytes());
    });
    for (case, verdict) in validator_errors(valid) {
        if let Verdict::Refused { .. } = verdict {
            push(&case.name, case.bytes);
        }
    }
    let regressions = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/regressions");
    let mut files: Vec<_> = std::fs::read_dir(regressions)
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    files.sort();
    for f in files {
        push(
            &format!("fuzz regression {}", f.display()),
            std::fs::read(&f).unwrap(),
        );
    }
    out
}

/// What aobake does with a file the Khronos validator reports errors in
/// (docs/import-policy.md).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// Refused, with an error that names this JSON path.
    Refused {
        /// Part of the error message: the JSON path of the offence.
        path: &'static str,
    },
    /// Accepted with a warning that contains this text.
    Warned {
        /// Part of the warning.
        about: &'static str,
    },
}

/// Files that the Khronos glTF validator reports errors in (each was
/// checked with it: its codes are in the case names) and that aobake once
/// accepted, built from a valid skinned, animated GLB (RiggedSimple), with
/// what aobake must do with each.
pub fn validator_errors(valid: &[u8]) -> Vec<(Case, Verdict)> {
    let (json, bin) = glb_parts(valid);
    let mut out = Vec::new();
    let mut two_bins = glb(&json, &bin);
    two_bins.extend(4u32.to_le_bytes());
    two_bins.extend(b"BIN\0");
    two_bins.extend([0u8; 4]);
    let total = two_bins.len() as u32;
    two_bins[8..12].copy_from_slice(&total.to_le_bytes());
    out.push((
        Case {
            name: "GLB with two BIN chunks (GLB_DUPLICATE_CHUNK)".to_owned(),
            bytes: two_bins,
        },
        Verdict::Refused { path: "chunk 2" },
    ));
    let mut edit = |name: &str, verdict: Verdict, f: &dyn Fn(&mut Value, &mut Vec<u8>)| {
        let (mut j, mut b) = (json.clone(), bin.clone());
        f(&mut j, &mut b);
        let case = Case {
            name: name.to_owned(),
            bytes: glb(&j, &b),
        };
        out.push((case, verdict));
    };
    use Verdict::{Refused, Warned};
    let position = json["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
        .as_u64()
        .unwrap() as usize;
    let normal = json["meshes"][0]["primitives"][0]["attributes"]["NORMAL"]
        .as_u64()
        .unwrap() as usize;
    let joints = json["meshes"][0]["primitives"][0]["attributes"]["JOINTS_0"]
        .as_u64()
        .unwrap() as usize;
    let weights = json["meshes"][0]["primitives"][0]["attributes"]["WEIGHTS_0"]
        .as_u64()
        .unwrap() as usize;
    let indices = json["meshes"][0]["primitives"][0]["indices"]
        .as_u64()
        .unwrap() as usize;
    let ibm = json["skins"][0]["inverseBindMatrices"].as_u64().unwrap() as usize;
    let view_of = |j: &Value, a: usize| j["accessors"][a]["bufferView"].as_u64().unwrap() as usize;
    // A joint node with a matrix (RiggedSimple's first joint) and the node
    // the animation moves (its second).
    let matrix_joint = json["skins"][0]["joints"][0].as_u64().unwrap();
    let animated = json["animations"][0]["channels"][0]["target"]["node"]
        .as_u64()
        .unwrap();
    assert!(json["nodes"][matrix_joint as usize]["matrix"].is_array());

    edit(
        "inverse-bind-matrix accessor with byteStride 64 (SKIN_IBM_ACCESSOR_WITH_BYTESTRIDE)",
        Refused {
            path: "skins[0].inverseBindMatrices",
        },
        &|j, _| {
            let v = view_of(j, ibm);
            j["bufferViews"][v]["byteStride"] = json!(64);
        },
    );
    edit(
        "index accessor with count 0 (VALUE_NOT_IN_RANGE)",
        Refused { path: "count" },
        &|j, _| {
            let a = &mut j["accessors"][indices];
            a["count"] = json!(0);
            drop_bounds(a);
        },
    );
    edit(
        "index accessor in a strided buffer view (MESH_PRIMITIVE_INDICES_ACCESSOR_WITH_BYTESTRIDE)",
        Refused {
            path: "meshes[0].primitives[0].indices",
        },
        &|j, _| {
            let v = view_of(j, indices);
            j["bufferViews"][v]["byteStride"] = json!(4);
            let count = j["accessors"][indices]["count"].as_u64().unwrap();
            j["accessors"][indices]["count"] = json!(count / 2);
        },
    );
    edit(
        "JOINTS_0 of unsigned 16 bits at its maximum, weight 0 (ACCESSOR_JOINTS_INDEX_OOB)",
        Warned {
            about: "joint indices past their skin had weight 0",
        },
        &|j, b| {
            // The last joint of vertex 0, whose weight is 0.
            let at = accessor_offset(j, joints) + 6;
            b[at..at + 2].copy_from_slice(&u16::MAX.to_le_bytes());
        },
    );
    edit(
        "WEIGHTS_0 of unsigned 32 bits (MESH_PRIMITIVE_ATTRIBUTES_ACCESSOR_INVALID_FORMAT)",
        Refused {
            path: "attributes.WEIGHTS_0",
        },
        &|j, _| {
            j["accessors"][weights]["componentType"] = json!(5125);
        },
    );
    edit(
        "POSITION of unsigned bytes without KHR_mesh_quantization (MESH_PRIMITIVE_ATTRIBUTES_ACCESSOR_INVALID_FORMAT)",
        Refused {
            path: "attributes.POSITION",
        },
        &|j, _| {
            let a = &mut j["accessors"][position];
            a["componentType"] = json!(5121);
            drop_bounds(a);
        },
    );
    edit(
        "skin that lists one joint twice (DUPLICATE_ELEMENTS)",
        Refused {
            path: "skins[0].joints",
        },
        &|j, _| {
            let first = j["skins"][0]["joints"][0].clone();
            j["skins"][0]["joints"][1] = first;
        },
    );
    edit(
        "inverse-bind-matrix accessor of unsigned shorts (SKIN_IBM_INVALID_FORMAT)",
        Refused {
            path: "skins[0].inverseBindMatrices",
        },
        &|j, _| {
            j["accessors"][ibm]["componentType"] = json!(5123);
        },
    );
    edit(
        "morph target with an attribute the primitive lacks (MESH_PRIMITIVE_MORPH_TARGET_NO_BASE_ACCESSOR)",
        Refused {
            path: "targets[0].TANGENT",
        },
        &|j, _| {
            j["meshes"][0]["primitives"][0]["targets"] = json!([{ "TANGENT": normal }]);
        },
    );
    edit(
        "primitives of one mesh with different numbers of targets (MESH_PRIMITIVES_UNEQUAL_TARGETS_COUNT)",
        Refused {
            path: "meshes[0].primitives[1].targets",
        },
        &|j, _| {
            let plain = j["meshes"][0]["primitives"][0].clone();
            j["meshes"][0]["primitives"][0]["targets"] = json!([{ "POSITION": normal }]);
            j["meshes"][0]["primitives"]
                .as_array_mut()
                .unwrap()
                .push(plain);
        },
    );
    edit(
        "primitive mode 2^32+4 (VALUE_NOT_IN_RANGE)",
        Refused {
            path: "meshes[0].primitives[0].mode",
        },
        &|j, _| {
            j["meshes"][0]["primitives"][0]["mode"] = json!((1u64 << 32) + 4);
        },
    );
    edit(
        "node with two parents, one of them the scene (SCENE_NON_ROOT_NODE)",
        Refused {
            path: "scenes[0].nodes[1]",
        },
        &|j, _| {
            j["scenes"][0]["nodes"]
                .as_array_mut()
                .unwrap()
                .push(json!(matrix_joint));
        },
    );
    edit(
        "cubic-spline sampler with one key (ANIMATION_SAMPLER_INPUT_ACCESSOR_TOO_FEW_ELEMENTS)",
        Refused {
            path: "animations[0].samplers[0].input",
        },
        &|j, _| {
            let sampler = j["animations"][0]["samplers"][0].clone();
            let input = sampler["input"].as_u64().unwrap() as usize;
            let output = sampler["output"].as_u64().unwrap() as usize;
            let mut keys = j["accessors"][input].clone();
            keys["count"] = json!(1);
            keys["max"] = keys["min"].clone();
            let mut values = j["accessors"][output].clone();
            values["count"] = json!(3);
            drop_bounds(&mut values);
            let accessors = j["accessors"].as_array_mut().unwrap();
            let n = accessors.len();
            accessors.extend([keys, values]);
            j["animations"][0]["samplers"][0] =
                json!({ "input": n, "output": n + 1, "interpolation": "CUBICSPLINE" });
        },
    );
    edit(
        "morph weights on a mesh without targets (MESH_INVALID_WEIGHTS_COUNT)",
        Refused {
            path: "meshes[0].weights",
        },
        &|j, _| {
            j["meshes"][0]["weights"] = json!([0.5]);
        },
    );
    edit(
        "two channels of one animation on one node's path (ANIMATION_DUPLICATE_TARGETS)",
        Refused {
            path: "animations[0].channels[",
        },
        &|j, _| {
            let first = j["animations"][0]["channels"][0].clone();
            j["animations"][0]["channels"]
                .as_array_mut()
                .unwrap()
                .push(first);
        },
    );
    edit(
        "animation channel on a node with a matrix (ANIMATION_CHANNEL_TARGET_NODE_MATRIX)",
        Refused {
            path: "animations[0].channels[0].target",
        },
        &|j, _| {
            j["animations"][0]["channels"][0]["target"]["node"] = json!(matrix_joint);
        },
    );
    edit(
        "node with both a matrix and TRS (NODE_MATRIX_TRS)",
        Refused { path: "nodes[" },
        &|j, _| {
            j["nodes"][matrix_joint as usize]["translation"] = json!([0.0, 0.0, 0.0]);
        },
    );
    edit(
        "float accessor marked normalized (ACCESSOR_NORMALIZED_INVALID)",
        Refused { path: "normalized" },
        &|j, _| {
            j["accessors"][weights]["normalized"] = json!(true);
        },
    );
    edit(
        "skin joints in two node trees (SKIN_NO_COMMON_ROOT)",
        Refused {
            path: "skins[0].joints",
        },
        &|j, _| {
            let nodes = j["nodes"].as_array_mut().unwrap();
            nodes.push(json!({ "name": "orphan" }));
            let orphan = nodes.len() - 1;
            let roots = j["scenes"][0]["nodes"].as_array_mut().unwrap();
            roots.push(json!(orphan));
            j["skins"][0]["joints"][1] = json!(orphan);
        },
    );
    edit(
        "skin skeleton below one of its joints (SKIN_SKELETON_INVALID)",
        Refused {
            path: "skins[0].skeleton",
        },
        &|j, _| {
            j["skins"][0]["skeleton"] = json!(animated);
        },
    );
    // Leniency that serves users: data AO computes from anyway.
    edit(
        "POSITION max that its data does not reach (ACCESSOR_MAX_MISMATCH)",
        Warned {
            about: "declare a min or max their data does not have",
        },
        &|j, _| {
            j["accessors"][position]["max"] = json!([9.0, 9.0, 9.0]);
        },
    );
    edit(
        "index min that its data does not have (ACCESSOR_MIN_MISMATCH)",
        Warned {
            about: "declare a min or max their data does not have",
        },
        &|j, _| {
            j["accessors"][indices]["min"] = json!([1]);
        },
    );
    edit(
        "a normal of length 2 (ACCESSOR_VECTOR3_NON_UNIT)",
        Warned {
            about: "normals were not of unit length; normalised",
        },
        &|j, b| {
            let at = accessor_offset(j, normal);
            b[at..at + 12].copy_from_slice(&[2f32, 0.0, 0.0].map(f32::to_le_bytes).concat());
            let a = &mut j["accessors"][normal];
            drop_bounds(a);
        },
    );
    edit(
        "a rotation key of length 2 (ACCESSOR_ANIMATION_SAMPLER_OUTPUT_NON_NORMALIZED_QUATERNION)",
        Warned {
            about: "rotation keys were not unit quaternions; normalised",
        },
        &|j, b| {
            let channel = j["animations"][0]["channels"]
                .as_array()
                .unwrap()
                .iter()
                .find(|c| c["target"]["path"] == "rotation")
                .unwrap()
                .clone();
            let sampler =
                &j["animations"][0]["samplers"][channel["sampler"].as_u64().unwrap() as usize];
            let output = sampler["output"].as_u64().unwrap() as usize;
            let at = accessor_offset(j, output);
            b[at..at + 16].copy_from_slice(&[0f32, 0.0, 0.0, 2.0].map(f32::to_le_bytes).concat());
            let a = &mut j["accessors"][output];
            drop_bounds(a);
        },
    );
    edit(
        "a node rotation of length 2 (VALUE_NOT_IN_RANGE)",
        Warned {
            about: "node rotations were not unit quaternions; normalised",
        },
        &|j, _| {
            j["nodes"][animated as usize]["rotation"] = json!([0.0, 0.0, 0.0, 2.0]);
        },
    );
    // Buffer views are structure, whoever reads them: one past the end of
    // its buffer (here one holding an image, which AO never decodes) is
    // refused.
    for (name, offset, length) in [
        (
            "buffer view past the end of its buffer, holding an image (BUFFER_VIEW_TOO_LONG)",
            bin.len() as u64 - 4,
            64u64,
        ),
        (
            "buffer view declaring 16 GiB, holding an image (BUFFER_VIEW_TOO_LONG)",
            0,
            1 << 34,
        ),
    ] {
        edit(
            name,
            Refused {
                path: "past the end of buffer 0",
            },
            &|j, _| {
                let views = j["bufferViews"].as_array_mut().unwrap();
                views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": length}));
                let v = views.len() - 1;
                j["images"] = json!([{ "bufferView": v, "mimeType": "image/png" }]);
            },
        );
    }
    // Sparse parts over POSITION: indices that do not strictly increase,
    // no elements, values in a strided view.
    let sparse = |j: &mut Value, b: &mut Vec<u8>, indices: &[u16], count: usize, stride: bool| {
        let at = accessor_offset(j, position);
        let mut ib: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
        while !ib.len().is_multiple_of(4) {
            ib.push(0);
        }
        let pad = if stride { 4 } else { 0 };
        let values: Vec<u8> = indices
            .iter()
            .flat_map(|&i| {
                let p = at + 12 * i as usize;
                b[p..p + 12]
                    .iter()
                    .copied()
                    .chain(std::iter::repeat_n(0, pad))
                    .collect::<Vec<u8>>()
            })
            .collect();
        let (istart, vstart) = (b.len(), b.len() + ib.len());
        b.extend(&ib);
        b.extend(&values);
        j["buffers"][0]["byteLength"] = json!(b.len());
        let views = j["bufferViews"].as_array_mut().unwrap();
        views.push(json!({"buffer": 0, "byteOffset": istart, "byteLength": ib.len()}));
        let mut vv = json!({"buffer": 0, "byteOffset": vstart, "byteLength": values.len()});
        if stride {
            vv["byteStride"] = json!(12 + pad);
        }
        views.push(vv);
        let n = views.len();
        j["accessors"][position]["sparse"] = json!({
            "count": count,
            "indices": {"bufferView": n - 2, "componentType": 5123},
            "values": {"bufferView": n - 1},
        });
    };
    edit(
        "sparse indices decreasing (ACCESSOR_SPARSE_INDICES_NON_INCREASING)",
        Refused {
            path: "sparse.indices",
        },
        &|j, b| sparse(j, b, &[1, 0], 2, false),
    );
    edit(
        "sparse index repeated (ACCESSOR_SPARSE_INDICES_NON_INCREASING)",
        Refused {
            path: "sparse.indices",
        },
        &|j, b| sparse(j, b, &[1, 1], 2, false),
    );
    edit(
        "sparse count 0 (VALUE_NOT_IN_RANGE)",
        Refused {
            path: "sparse.count",
        },
        &|j, b| sparse(j, b, &[0, 1], 0, false),
    );
    edit(
        "sparse values in a strided buffer view (BUFFER_VIEW_INVALID_BYTE_STRIDE)",
        Refused {
            path: "sparse.values",
        },
        &|j, b| sparse(j, b, &[0, 1], 2, true),
    );
    // Images AO never reads: warned about, as the texture exception says.
    edit(
        "image in a buffer view without mimeType (UNSATISFIED_DEPENDENCY)",
        Warned {
            about: "images stored in buffer views",
        },
        &|j, _| {
            let v = view_of(j, ibm);
            j["images"] = json!([{ "bufferView": v }]);
        },
    );
    edit(
        "image with a buffer view that does not exist (UNRESOLVED_REFERENCE)",
        Warned {
            about: "problems in materials, textures, images",
        },
        &|j, _| {
            j["images"] = json!([{ "bufferView": 99, "mimeType": "image/png" }]);
        },
    );
    edit(
        "image with both a buffer view and a uri (ONE_OF_MISMATCH)",
        Warned {
            about: "images stored in buffer views",
        },
        &|j, _| {
            let v = view_of(j, ibm);
            j["images"] = json!([{ "bufferView": v, "mimeType": "image/png", "uri": "x.png" }]);
        },
    );
    out
}
