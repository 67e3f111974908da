//! The GLB an export writes (its one buffer and its accessors), and the
//! glTF JSON's top-level arrays, shared by the families' parts.

use serde_json::{Map, Value, json};

/// What one family's part of an export adds: its fields of
/// `extras.aobake`, and the coefficient rows it stores.
pub(super) struct Specific {
    pub(super) extras: Map<String, Value>,
    pub(super) rows: usize,
    pub(super) summary: String,
}

/// A top-level array of the glTF JSON, empty if the file has none (nothing
/// is added to the file).
pub(super) fn existing<'a>(json: &'a mut Value, key: &str) -> &'a mut [Value] {
    json.get_mut(key)
        .and_then(Value::as_array_mut)
        .map_or(&mut [], Vec::as_mut_slice)
}

/// A top-level array of the glTF JSON to add to (created if absent).
pub(super) fn array<'a>(json: &'a mut Value, key: &str) -> &'a mut Vec<Value> {
    let root = json.as_object_mut().expect("a glTF root is an object");
    let entry = root.entry(key).or_insert_with(|| Value::Array(Vec::new()));
    if !entry.is_array() {
        *entry = Value::Array(Vec::new());
    }
    entry.as_array_mut().expect("just made an array")
}

/// The GLB being written: its binary chunk.
#[derive(Debug, Default)]
pub(super) struct Glb {
    pub(super) bin: Vec<u8>,
}

impl Glb {
    /// Appends `bytes` at a 4-byte boundary; their offset.
    pub(super) fn append(&mut self, bytes: &[u8]) -> usize {
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        let at = self.bin.len();
        self.bin.extend_from_slice(bytes);
        at
    }

    /// A FLOAT vertex attribute accessor of `kind` over `values` in a view
    /// of its own; its index.
    pub(super) fn accessor(&mut self, json: &mut Value, values: &[f32], kind: &str) -> usize {
        self.data_accessor(json, values, kind, Some(34962))
    }

    /// A FLOAT accessor of `kind` over `values` in a view of its own, the
    /// view bound to `target` (34962: vertex attributes; `None` for other
    /// data, as animation keys); its index.
    pub(super) fn data_accessor(
        &mut self,
        json: &mut Value,
        values: &[f32],
        kind: &str,
        target: Option<u32>,
    ) -> usize {
        let width = match kind {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            _ => 4,
        };
        let bytes: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
        let offset = self.append(&bytes);
        let views = array(json, "bufferViews");
        let mut view = json!({
            "buffer": 0,
            "byteOffset": offset,
            "byteLength": bytes.len(),
        });
        if let Some(target) = target {
            view["target"] = target.into();
        }
        views.push(view);
        let view = views.len() - 1;
        let accessors = array(json, "accessors");
        accessors.push(json!({
            "bufferView": view,
            "componentType": 5126,
            "count": values.len() / width,
            "type": kind,
        }));
        accessors.len() - 1
    }

    /// An UNSIGNED_INT SCALAR accessor over `values` in a view of its
    /// own, bound to `target` (34963: indices; `None` for other data);
    /// its index.
    pub(super) fn u32_accessor(
        &mut self,
        json: &mut Value,
        values: &[u32],
        target: Option<u32>,
    ) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
        let offset = self.append(&bytes);
        let mut view = json!({ "buffer": 0, "byteOffset": offset, "byteLength": bytes.len() });
        if let Some(target) = target {
            view["target"] = target.into();
        }
        array(json, "bufferViews").push(view);
        let view = array(json, "bufferViews").len() - 1;
        let accessors = array(json, "accessors");
        accessors.push(json!({
            "bufferView": view,
            "componentType": 5125,
            "count": values.len(),
            "type": "SCALAR",
        }));
        accessors.len() - 1
    }

    /// The file: header, JSON chunk (padded with spaces), BIN chunk
    /// (padded with zeros).
    pub(super) fn finish(mut self, json: &Value) -> Vec<u8> {
        let mut text = serde_json::to_vec(json).expect("JSON serialises");
        text.resize(text.len().next_multiple_of(4), b' ');
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        let total = 12 + 8 + text.len() + 8 + self.bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(text.len() as u32).to_le_bytes());
        out.extend_from_slice(&0x4E4F_534Au32.to_le_bytes());
        out.extend_from_slice(&text);
        out.extend_from_slice(&(self.bin.len() as u32).to_le_bytes());
        out.extend_from_slice(&0x004E_4942u32.to_le_bytes());
        out.extend_from_slice(&self.bin);
        out
    }
}
