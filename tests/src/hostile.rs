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

fn glb_parts(glb: &[u8]) -> (Value, Vec<u8>) {
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
