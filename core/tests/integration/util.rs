//! Fixtures: paths to bundled and shared characters, and a builder of small
//! glTF files to mutate into broken ones.

#![allow(dead_code, unreachable_pub)]

use std::path::{Path, PathBuf};

use aobake_core::{Imported, Limits, SideFile, Upload, import_character};
use base64::Engine as _;
use serde_json::{Value, json};

pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// `../shared/data` beside the repository, when it exists.
pub fn shared_data() -> Option<PathBuf> {
    let dir = repo().join("../shared/data");
    dir.is_dir().then_some(dir)
}

/// A character file by name: bundled copies first, then the shared data.
pub fn character_path(file: &str) -> Option<PathBuf> {
    let bundled = repo().join("tests/data/characters");
    [Some(bundled), shared_data()]
        .into_iter()
        .flatten()
        .filter_map(|dir| std::fs::read_dir(dir).ok())
        .flat_map(|entries| entries.flatten())
        .map(|entry| entry.path().join(file))
        .find(|candidate| candidate.is_file())
}

pub fn load(path: &Path) -> Imported {
    let bytes = std::fs::read(path).unwrap();
    import_character(Upload::single(&bytes), &Limits::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every character file in the shared data and the bundled samples,
/// deduplicated by file name.
pub fn all_characters() -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = Vec::new();
    let bundled = repo().join("tests/data/characters");
    for dir in [Some(bundled), shared_data()].into_iter().flatten() {
        let mut dirs: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .collect();
        dirs.sort();
        for d in dirs.into_iter().filter(|d| d.is_dir()) {
            for f in std::fs::read_dir(&d).unwrap().flatten().map(|e| e.path()) {
                let ext = f.extension().and_then(|e| e.to_str()).unwrap_or("");
                if (ext == "glb" || ext == "gltf")
                    && !out.iter().any(|o| o.file_name() == f.file_name())
                {
                    out.push(f);
                }
            }
        }
    }
    out
}

/// A small glTF under construction: JSON plus one binary buffer.
#[derive(Clone)]
pub struct Gltf {
    pub json: Value,
    pub bin: Vec<u8>,
}

pub const FLOAT: u32 = 5126;
pub const U8: u32 = 5121;
pub const U16: u32 = 5123;
pub const U32: u32 = 5125;

impl Gltf {
    pub fn new() -> Self {
        Self {
            json: json!({
                "asset": {"version": "2.0"},
                "buffers": [], "bufferViews": [], "accessors": [],
                "nodes": [], "meshes": [], "scenes": [{"nodes": []}], "scene": 0
            }),
            bin: Vec::new(),
        }
    }

    fn push(&mut self, key: &str, value: Value) -> usize {
        let arr = self.json[key].as_array_mut().unwrap();
        arr.push(value);
        arr.len() - 1
    }

    /// Adds a tightly packed accessor over new bytes.
    pub fn accessor(&mut self, bytes: &[u8], component_type: u32, ty: &str, count: usize) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        let view = self.push(
            "bufferViews",
            json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()}),
        );
        self.push(
            "accessors",
            json!({"bufferView": view, "componentType": component_type, "type": ty, "count": count}),
        )
    }

    /// Byte offset in `bin` of an accessor's first element.
    pub fn accessor_offset(&self, accessor: usize) -> usize {
        let view = self.json["accessors"][accessor]["bufferView"]
            .as_u64()
            .unwrap() as usize;
        let view_offset = self.json["bufferViews"][view]["byteOffset"]
            .as_u64()
            .unwrap() as usize;
        view_offset
            + self.json["accessors"][accessor]["byteOffset"]
                .as_u64()
                .unwrap_or(0) as usize
    }

    /// The triangle (0,0,0), (1,0,0), (0,1,0) as a VEC3 accessor.
    pub fn unit_triangle(&mut self) -> usize {
        self.floats(&[0., 0., 0., 1., 0., 0., 0., 1., 0.], "VEC3")
    }

    pub fn floats(&mut self, values: &[f32], ty: &str) -> usize {
        let width = match ty {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            "MAT4" => 16,
            _ => panic!("{ty}"),
        };
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(&bytes, FLOAT, ty, values.len() / width)
    }

    pub fn u16s(&mut self, values: &[u16], ty: &str, count: usize) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(&bytes, U16, ty, count)
    }

    pub fn node(&mut self, node: Value) -> usize {
        self.push("nodes", node)
    }

    pub fn mesh(&mut self, mesh: Value) -> usize {
        self.push("meshes", mesh)
    }

    pub fn add_root(&mut self, node: usize) {
        self.json["scenes"][0]["nodes"]
            .as_array_mut()
            .unwrap()
            .push(json!(node));
    }

    fn finish_buffers(&self, uri: Option<String>) -> Value {
        let mut json = self.json.clone();
        let mut buffer = json!({"byteLength": self.bin.len()});
        if let Some(uri) = uri {
            buffer["uri"] = json!(uri);
        }
        json["buffers"] = json!([buffer]);
        json
    }

    /// As a GLB.
    pub fn glb(&self) -> Vec<u8> {
        let mut json = serde_json::to_vec(&self.finish_buffers(None)).unwrap();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        out
    }

    /// As a `.gltf` with the buffer in a data URI.
    pub fn embedded(&self) -> Vec<u8> {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&self.bin)
        );
        serde_json::to_vec(&self.finish_buffers(Some(uri))).unwrap()
    }

    /// As a `.gltf` whose buffer is the side file `name`.
    pub fn with_side_file(&self, uri: &str, name: &str) -> (Vec<u8>, Vec<SideFile>) {
        let json = serde_json::to_vec(&self.finish_buffers(Some(uri.to_owned()))).unwrap();
        (
            json,
            vec![SideFile {
                name: name.to_owned(),
                bytes: self.bin.clone(),
            }],
        )
    }

    pub fn import(&self) -> Result<Imported, aobake_core::ImportError> {
        import_character(Upload::single(&self.glb()), &Limits::default())
    }
}

/// A two-joint rig: a vertical strip of 3 quads (8 vertices) from y=0 to
/// y=3, the lower half bound to joint 0 at the origin, the upper half to
/// joint 1 at y=1.5, and a clip that bends joint 1 by 90° about z over one
/// second. Returns the builder and the skinned mesh node.
pub fn tiny_rig() -> Gltf {
    let mut g = Gltf::new();
    let mut positions = Vec::new();
    for row in 0..4 {
        for x in [-0.5f32, 0.5] {
            positions.extend([x, row as f32, 0.0]);
        }
    }
    let pos = g.floats(&positions, "VEC3");
    let indices: Vec<u16> = (0..3u16)
        .flat_map(|r| {
            let b = r * 2;
            [b, b + 1, b + 3, b, b + 3, b + 2]
        })
        .collect();
    let idx = g.u16s(&indices, "SCALAR", indices.len());
    let joints: Vec<u16> = (0..8)
        .flat_map(|v| [if v < 4 { 0 } else { 1 }, 0, 0, 0])
        .collect();
    let joints = g.u16s(&joints, "VEC4", 8);
    let weights: Vec<f32> = (0..8).flat_map(|_| [1.0, 0.0, 0.0, 0.0]).collect();
    let weights = g.floats(&weights, "VEC4");
    let ibm: Vec<f32> = glam::Mat4::IDENTITY
        .to_cols_array()
        .into_iter()
        .chain(glam::Mat4::from_translation(glam::Vec3::new(0.0, -1.5, 0.0)).to_cols_array())
        .collect();
    let ibm = g.floats(&ibm, "MAT4");
    let mesh = g.mesh(json!({"primitives": [{
        "attributes": {"POSITION": pos, "JOINTS_0": joints, "WEIGHTS_0": weights},
        "indices": idx
    }]}));
    let root = g.node(json!({"name": "root", "children": [1]}));
    let _upper = g.node(json!({"name": "upper", "translation": [0.0, 1.5, 0.0]}));
    let skinned = g.node(json!({"name": "skin", "mesh": mesh, "skin": 0}));
    g.json["skins"] = json!([{"joints": [root, 1], "inverseBindMatrices": ibm}]);
    g.add_root(root);
    g.add_root(skinned);
    let times = g.floats(&[0.0, 1.0], "SCALAR");
    let half = std::f32::consts::FRAC_PI_4;
    let rotations = g.floats(
        &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, half.sin(), half.cos()],
        "VEC4",
    );
    g.json["animations"] = json!([{
        "name": "bend",
        "samplers": [{"input": times, "output": rotations, "interpolation": "LINEAR"}],
        "channels": [{"sampler": 0, "target": {"node": 1, "path": "rotation"}}]
    }]);
    g
}

/// Bake inputs as if uploaded; the digests are placeholders.
pub fn inputs(
    character: &aobake_core::Character,
    clips: &[aobake_core::Clip],
) -> aobake_core::bake::BakeInputs {
    aobake_core::bake::BakeInputs {
        character: character.clone(),
        clips: clips.to_vec(),
        character_digest: "character-digest".into(),
        clip_digests: Vec::new(),
        warnings: Vec::new(),
    }
}
