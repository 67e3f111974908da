//! A texel asset in the glTF export ([`super::export_gltf`]): the
//! character over its atlas, so that every glTF viewer shows the static
//! AO and an engine can play the model per pixel.
//!
//! * Each primitive is re-indexed over the atlas's vertices that its
//!   triangles use, in atlas order (a vertex on a seam between charts
//!   becomes one vertex per chart): every attribute and morph target is
//!   gathered as it was (same component type, type and normalisation),
//!   the indices become UNSIGNED_INT triangles, and the atlas's UVs are
//!   the primitive's next free `TEXCOORD_n`.
//! * Each primitive gets a copy of its material (or a new one) whose
//!   standard `occlusionTexture` is the static AO over that set: an 8-bit
//!   grey PNG holding `1 − AO` (glTF's convention: 1 is unoccluded), the
//!   model averaged over the clips' frames per texel, dilated past the
//!   charts.
//! * `extras.aobake.basis` lists the basis textures ([`TexelModel::basis`],
//!   one per weight) as 16-bit grey PNGs in `images`, each with the
//!   `offset` and `scale` that decode it: `value = offset + scale · q /
//!   65535`. Per pixel `ao = clamp(Σ_k w_k · basis_k(uv), 0, 1)`, with
//!   the pose's weights `w` from `layout` and `sections`, as for the
//!   vertex methods.
//! * `extras.aobake.primitives[i].vertex_of` is an accessor (UNSIGNED_INT)
//!   giving each exported vertex's vertex in aobake's order, so that a
//!   reader can compare with `aobake eval`, which samples the texture at
//!   each vertex's first atlas vertex.

use std::collections::BTreeMap;

use serde_json::{Map, Value, json};

use super::glb::{Glb, Specific, array};
use crate::{Character, image::ImageError, method::texel::TexelModel};

/// How `extras.aobake` says the basis images decode.
const BASIS_ENCODING: &str =
    "16-bit grey PNG, texel row 0 at v = 0: value = offset + scale * sample / 65535";

/// Writes the texel asset's part of the export (see the module's notes).
#[allow(clippy::too_many_arguments)]
pub(super) fn write(
    json: &mut Value,
    out: &mut Glb,
    character: &Character,
    mesh_of_node: &BTreeMap<usize, usize>,
    model: &TexelModel,
    static_ao: &[f32],
    frames: usize,
    warnings: &mut Vec<String>,
) -> Result<Specific, String> {
    let atlas = &model.atlas;
    let (width, height) = (atlas.width, atlas.height);
    let image_error = |e: ImageError| e.to_string();

    // The static occlusion texture: 1 − AO per texel, dilated.
    let occlusion: Vec<u8> = atlas
        .image(static_ao)
        .iter()
        .map(|&a| (255.0 * (1.0 - a.clamp(0.0, 1.0))).round() as u8)
        .collect();
    let png = crate::image::encode_grey8_png(&occlusion, width, height).map_err(image_error)?;
    let static_image = push_image(json, out, &png, "aobake occlusion (1 - AO)");
    array(json, "samplers").push(json!({
        "magFilter": 9729,
        "minFilter": 9987,
        "wrapS": 33071,
        "wrapT": 33071,
    }));
    let sampler = array(json, "samplers").len() - 1;
    array(json, "textures").push(json!({ "sampler": sampler, "source": static_image }));
    let texture = array(json, "textures").len() - 1;

    // The basis textures, quantised per texture.
    let basis = model.basis().map_err(|e| e.to_string())?;
    let mut layers = Vec::with_capacity(basis.len());
    for (k, layer) in basis.iter().enumerate() {
        let (lo, hi) = layer
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        let (lo, hi) = if lo.is_finite() && hi.is_finite() {
            (lo, hi)
        } else {
            (0.0, 0.0)
        };
        let scale = if hi > lo { hi - lo } else { 1.0 };
        let samples: Vec<u16> = layer
            .iter()
            .map(|&v| (65535.0 * ((v - lo) / scale)).round().clamp(0.0, 65535.0) as u16)
            .collect();
        let png = crate::image::encode_grey16_png(&samples, width, height).map_err(image_error)?;
        let image = push_image(json, out, &png, &format!("aobake basis {k}"));
        layers.push(json!({ "image": image, "offset": lo, "scale": scale }));
    }

    // Each primitive over its atlas vertices.
    let mut local = vec![u32::MAX; atlas.xref.len()];
    let mut order = Vec::with_capacity(character.primitives.len());
    let mut replaced_occlusion = false;
    for p in &character.primitives {
        let mesh = mesh_of_node[&p.node];
        let count = p.vertices.len();
        let at = |json: &Value| json["meshes"][mesh]["primitives"][p.primitive].clone();
        let primitive = at(json);
        // A primitive no triangle of the atlas is on (all of its
        // triangles had no area) keeps its own vertices, and is not listed.
        if p.triangles.is_empty() {
            continue;
        }
        let triangles = atlas
            .triangles
            .get(p.triangles.clone())
            .ok_or_else(|| "the asset's atlas has fewer triangles".to_owned())?;
        let mut used: Vec<u32> = triangles.iter().flatten().copied().collect();
        used.sort_unstable();
        used.dedup();
        let mut source = Vec::with_capacity(used.len());
        for (i, &a) in used.iter().enumerate() {
            local[a as usize] = i as u32;
            let v = atlas.xref[a as usize] as usize;
            if !p.vertices.contains(&v) {
                return Err(format!(
                    "meshes[{}].primitives[{}]: the atlas joins it to another primitive's vertex",
                    p.mesh, p.primitive
                ));
            }
            source.push((v - p.vertices.start) as u32);
        }
        let fail = |what: String| format!("meshes[{}].primitives[{}]: {what}", p.mesh, p.primitive);
        let mut attributes = primitive["attributes"]
            .as_object()
            .cloned()
            .unwrap_or_default();
        gather_all(json, out, &mut attributes, count, &source).map_err(fail)?;
        let set = (0..)
            .find(|n| !attributes.contains_key(&format!("TEXCOORD_{n}")))
            .expect("a free TEXCOORD_n");
        let uvs: Vec<f32> = used.iter().flat_map(|&a| atlas.uvs[a as usize]).collect();
        attributes.insert(
            format!("TEXCOORD_{set}"),
            out.accessor(json, &uvs, "VEC2").into(),
        );
        let mut targets = primitive["targets"].as_array().cloned().unwrap_or_default();
        for (t, target) in targets.iter_mut().enumerate() {
            let Some(target) = target.as_object_mut() else {
                continue;
            };
            gather_all(json, out, target, count, &source)
                .map_err(|e| fail(format!("targets[{t}].{e}")))?;
        }
        let indices: Vec<u32> = triangles
            .iter()
            .flatten()
            .map(|&a| local[a as usize])
            .collect();
        let indices = out.u32_accessor(json, &indices, Some(34963));
        let vertex_of: Vec<u32> = source
            .iter()
            .map(|&s| (p.vertices.start + s as usize) as u32)
            .collect();
        let vertex_of = out.u32_accessor(json, &vertex_of, None);
        // Its own material: the file's with the occlusion texture.
        let mut material = primitive
            .get("material")
            .and_then(Value::as_u64)
            .and_then(|m| json["materials"].get(m as usize).cloned())
            .unwrap_or_else(|| json!({ "name": "aobake occlusion" }));
        if let Some(m) = material.as_object_mut() {
            replaced_occlusion |= m.contains_key("occlusionTexture");
            m.insert(
                "occlusionTexture".into(),
                json!({ "index": texture, "texCoord": set }),
            );
        }
        array(json, "materials").push(material);
        let material = array(json, "materials").len() - 1;
        let target = &mut json["meshes"][mesh]["primitives"][p.primitive];
        target["attributes"] = Value::Object(attributes);
        if !targets.is_empty() {
            target["targets"] = Value::Array(targets);
        }
        target["indices"] = indices.into();
        target["mode"] = 4.into();
        target["material"] = material.into();
        order.push(json!({
            "node": p.node,
            "mesh": mesh,
            "primitive": p.primitive,
            "first": p.vertices.start,
            "count": count,
            "exported": used.len(),
            "texcoord": set,
            "vertex_of": vertex_of,
        }));
    }
    if replaced_occlusion {
        warnings.push(
            "a material's own occlusionTexture was replaced by the baked static AO".to_owned(),
        );
    }
    let extras = json!({
        "family": "texel",
        "primitives": order,
        "atlas": { "width": width, "height": height, "texels": atlas.texels.len() },
        "static": {
            "texture": texture,
            "image": static_image,
            "frames": frames,
            "encoding": "8-bit grey PNG of 1 - AO (glTF's occlusion: 1 is unoccluded), the model averaged over the frames",
        },
        "rows": basis.len(),
        "basis": layers,
        "basis_encoding": BASIS_ENCODING,
        "ao": "per pixel: clamp(sum_k w_k * basis_k(uv), 0, 1), bilinear, uv the primitive's TEXCOORD_<texcoord>",
    });
    Ok(Specific {
        extras: extras.as_object().cloned().unwrap_or_default(),
        rows: basis.len(),
        summary: format!(
            "the static AO over {frames} clip frames as each material's occlusionTexture on a {width} × {height} atlas (a new TEXCOORD set), {} basis textures as 16-bit PNGs listed in extras.aobake",
            basis.len()
        ),
    })
}

/// A PNG image in the GLB's buffer; its index in `images`.
fn push_image(json: &mut Value, out: &mut Glb, png: &[u8], name: &str) -> usize {
    let offset = out.append(png);
    array(json, "bufferViews").push(json!({
        "buffer": 0,
        "byteOffset": offset,
        "byteLength": png.len(),
    }));
    let view = array(json, "bufferViews").len() - 1;
    array(json, "images").push(json!({
        "name": name,
        "mimeType": "image/png",
        "bufferView": view,
    }));
    array(json, "images").len() - 1
}

/// Every attribute of `map` (a primitive's attributes, or one morph
/// target's) replaced by its accessor [`gather`]ed at `source`; the error
/// names the attribute.
fn gather_all(
    json: &mut Value,
    out: &mut Glb,
    map: &mut Map<String, Value>,
    count: usize,
    source: &[u32],
) -> Result<(), String> {
    for (name, accessor) in map.iter_mut() {
        let index = accessor
            .as_u64()
            .ok_or_else(|| format!("{name} is no accessor"))?;
        *accessor = gather(json, out, index as usize, count, source, name == "POSITION")
            .map_err(|e| format!("{name}: {e}"))?
            .into();
    }
    Ok(())
}

/// A vertex attribute's accessor gathered at `source` (indices into its
/// `count` elements) into a new accessor of the same component type,
/// type and normalisation, with bounds when `bounds` (POSITION's, which
/// glTF requires); its index. The elements are read as the file lays
/// them out: in a view with or without a stride, with sparse
/// substitutions, or zeros without a view.
fn gather(
    json: &mut Value,
    out: &mut Glb,
    index: usize,
    count: usize,
    source: &[u32],
    bounds: bool,
) -> Result<usize, String> {
    let accessor = json["accessors"]
        .get(index)
        .cloned()
        .ok_or("no such accessor")?;
    let component_type = accessor["componentType"].as_u64().unwrap_or(0);
    let component = match component_type {
        5120 | 5121 => 1,
        5122 | 5123 => 2,
        5125 | 5126 => 4,
        other => return Err(format!("component type {other}")),
    };
    let kind = accessor["type"].as_str().unwrap_or("").to_owned();
    let components = match kind.as_str() {
        "SCALAR" => 1,
        "VEC2" => 2,
        "VEC3" => 3,
        "VEC4" => 4,
        other => return Err(format!("a vertex attribute of type {other:?}")),
    };
    let element = component * components;
    // Every attribute of a primitive has its POSITION's count.
    if accessor["count"].as_u64() != Some(count as u64) {
        return Err(format!("{} elements, not {count}", accessor["count"]));
    }
    let bin = &out.bin;
    let slice = |at: u64, len: usize| -> Result<&[u8], String> {
        usize::try_from(at)
            .ok()
            .and_then(|at| bin.get(at..at.checked_add(len)?))
            .ok_or_else(|| "its data lie outside the buffer".to_owned())
    };
    // A view's start, its stride and its length.
    let view_of = |v: &Value| -> Result<(u64, Option<u64>, u64), String> {
        let view = v
            .as_u64()
            .and_then(|v| json["bufferViews"].get(v as usize))
            .ok_or("no such buffer view")?;
        Ok((
            view["byteOffset"].as_u64().unwrap_or(0),
            view["byteStride"].as_u64(),
            view["byteLength"].as_u64().unwrap_or(0),
        ))
    };
    // Where `len` bytes at `at` within a view begin in the buffer, if
    // they lie within the view.
    let within = |(offset, _, length): (u64, Option<u64>, u64), at: u64, len: u64| {
        at.checked_add(len)
            .filter(|&end| end <= length)
            .and_then(|_| offset.checked_add(at))
            .ok_or_else(|| "its data lie outside their buffer view".to_owned())
    };
    let mut data = vec![0u8; count * element];
    if let Some(view) = accessor.get("bufferView") {
        let view = view_of(view)?;
        let stride = view.1.unwrap_or(element as u64);
        if stride < element as u64 {
            return Err(format!(
                "a stride of {stride} bytes for elements of {element}"
            ));
        }
        let first = accessor["byteOffset"].as_u64().unwrap_or(0);
        for (i, chunk) in data.chunks_exact_mut(element).enumerate() {
            let at = (i as u64)
                .checked_mul(stride)
                .and_then(|d| first.checked_add(d))
                .ok_or("its data lie outside their buffer view")?;
            chunk.copy_from_slice(slice(within(view, at, element as u64)?, element)?);
        }
    }
    if let Some(sparse) = accessor.get("sparse") {
        let n = sparse["count"]
            .as_u64()
            .ok_or("a sparse accessor without count")? as usize;
        let width = match sparse["indices"]["componentType"].as_u64() {
            Some(5121) => 1,
            Some(5123) => 2,
            Some(5125) => 4,
            _ => return Err("sparse indices of another type".into()),
        };
        let too_many = || "too many sparse values".to_owned();
        let (indices_len, values_len) = (
            n.checked_mul(width).ok_or_else(too_many)?,
            n.checked_mul(element).ok_or_else(too_many)?,
        );
        let at = within(
            view_of(&sparse["indices"]["bufferView"])?,
            sparse["indices"]["byteOffset"].as_u64().unwrap_or(0),
            indices_len as u64,
        )?;
        let values = within(
            view_of(&sparse["values"]["bufferView"])?,
            sparse["values"]["byteOffset"].as_u64().unwrap_or(0),
            values_len as u64,
        )?;
        let indices = slice(at, indices_len)?.to_vec();
        let replaced = slice(values, values_len)?.to_vec();
        for (j, index) in indices.chunks_exact(width).enumerate() {
            let mut i = 0usize;
            for (b, &byte) in index.iter().enumerate() {
                i |= usize::from(byte) << (8 * b);
            }
            let to = data
                .get_mut(i * element..(i + 1) * element)
                .ok_or("a sparse index past the end")?;
            to.copy_from_slice(&replaced[j * element..(j + 1) * element]);
        }
    }
    // Each element starts on 4 bytes (glTF's rule for vertex attributes).
    let stride = element.next_multiple_of(4);
    let mut gathered = vec![0u8; source.len() * stride];
    for (chunk, &s) in gathered.chunks_exact_mut(stride).zip(source) {
        let s = s as usize;
        chunk[..element].copy_from_slice(&data[s * element..(s + 1) * element]);
    }
    let offset = out.append(&gathered);
    let mut view = json!({
        "buffer": 0,
        "byteOffset": offset,
        "byteLength": gathered.len(),
        "target": 34962,
    });
    if stride != element {
        view["byteStride"] = stride.into();
    }
    array(json, "bufferViews").push(view);
    let view = array(json, "bufferViews").len() - 1;
    let mut written = Map::new();
    written.insert("bufferView".into(), view.into());
    written.insert("componentType".into(), component_type.into());
    written.insert("count".into(), source.len().into());
    written.insert("type".into(), kind.into());
    if accessor["normalized"].as_bool() == Some(true) {
        written.insert("normalized".into(), true.into());
    }
    if bounds && !source.is_empty() {
        // In the component type's own numbers (a quantised POSITION's
        // integers), as glTF states bounds.
        let value = |bytes: &[u8]| -> Value {
            match component_type {
                5120 => json!(bytes[0] as i8),
                5121 => json!(bytes[0]),
                5122 => json!(i16::from_le_bytes([bytes[0], bytes[1]])),
                5123 => json!(u16::from_le_bytes([bytes[0], bytes[1]])),
                5125 => json!(u32::from_le_bytes(bytes[..4].try_into().expect("4 bytes"))),
                _ => json!(f32::from_le_bytes(bytes[..4].try_into().expect("4 bytes"))),
            }
        };
        let number = |v: &Value| v.as_f64().unwrap_or(0.0);
        let mut lo: Vec<Value> = Vec::with_capacity(components);
        let mut hi: Vec<Value> = Vec::with_capacity(components);
        for c in 0..components {
            let (mut min, mut max) = (None::<Value>, None::<Value>);
            for chunk in gathered.chunks_exact(stride) {
                let v = value(&chunk[c * component..(c + 1) * component]);
                if min.as_ref().is_none_or(|m| number(&v) < number(m)) {
                    min = Some(v.clone());
                }
                if max.as_ref().is_none_or(|m| number(&v) > number(m)) {
                    max = Some(v);
                }
            }
            lo.push(min.unwrap_or_default());
            hi.push(max.unwrap_or_default());
        }
        written.insert("min".into(), Value::Array(lo));
        written.insert("max".into(), Value::Array(hi));
    }
    array(json, "accessors").push(Value::Object(written));
    Ok(array(json, "accessors").len() - 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bytes of accessor `index` as `gather` wrote it, and its JSON.
    fn written(json: &Value, out: &Glb, index: usize) -> (Vec<u8>, Value) {
        let a = json["accessors"][index].clone();
        let view = &json["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
        let at = view["byteOffset"].as_u64().unwrap() as usize;
        let len = view["byteLength"].as_u64().unwrap() as usize;
        (out.bin[at..at + len].to_vec(), a)
    }

    #[test]
    fn gather_reads_strided_sparse_and_quantised_attributes_as_the_file_lays_them_out() {
        let mut out = Glb::default();
        // Three VEC3 u16 positions (quantised), interleaved in a 12-byte
        // stride after 2 bytes of something else.
        let mut interleaved = Vec::new();
        for p in [[1u16, 2, 3], [40, 50, 60], [7, 8, 900]] {
            interleaved.extend([0xAA, 0xBB]);
            for c in p {
                interleaved.extend(c.to_le_bytes());
            }
            interleaved.extend([0xCC; 4]);
        }
        let a = out.append(&interleaved);
        // Sparse: element 1 of an all-zero VEC2 float accessor set to (5, 6).
        let sparse_indices = out.append(&[1u8]);
        let sparse_values = out.append(&[5.0f32, 6.0].map(f32::to_le_bytes).concat());
        let mut json = json!({
            "bufferViews": [
                {"buffer": 0, "byteOffset": a, "byteLength": 36, "byteStride": 12},
                {"buffer": 0, "byteOffset": sparse_indices, "byteLength": 1},
                {"buffer": 0, "byteOffset": sparse_values, "byteLength": 8},
            ],
            "accessors": [
                {"bufferView": 0, "byteOffset": 2, "componentType": 5123, "count": 3, "type": "VEC3"},
                {"componentType": 5126, "count": 3, "type": "VEC2", "sparse": {
                    "count": 1,
                    "indices": {"bufferView": 1, "componentType": 5121},
                    "values": {"bufferView": 2}}},
                {"bufferView": 0, "byteOffset": 30, "componentType": 5123, "count": 3, "type": "VEC3"},
                {"bufferView": 0, "byteOffset": 2, "componentType": 5123, "count": 3, "type": "VEC3",
                 "sparse": {"count": 1, "indices": {"bufferView": 1, "componentType": 5121, "byteOffset": 1},
                            "values": {"bufferView": 2}}},
            ],
        });
        // Gathered in another order, one repeated.
        let source = [2u32, 0, 2];
        let positions = gather(&mut json, &mut out, 0, 3, &source, true).unwrap();
        let (bytes, accessor) = written(&json, &out, positions);
        // 6-byte elements padded to 8, with a stride saying so.
        let view = &json["bufferViews"][accessor["bufferView"].as_u64().unwrap() as usize];
        assert_eq!(view["byteStride"], 8);
        let element = |i: usize| -> Vec<u16> {
            (0..3)
                .map(|c| u16::from_le_bytes([bytes[8 * i + 2 * c], bytes[8 * i + 2 * c + 1]]))
                .collect()
        };
        assert_eq!(element(0), [7, 8, 900]);
        assert_eq!(element(1), [1, 2, 3]);
        assert_eq!(element(2), [7, 8, 900]);
        // A quantised POSITION's bounds in its own integers.
        assert_eq!(accessor["min"], json!([1, 2, 3]));
        assert_eq!(accessor["max"], json!([7, 8, 900]));
        assert_eq!(
            (
                accessor["componentType"].as_u64(),
                accessor["count"].as_u64()
            ),
            (Some(5123), Some(3))
        );
        // Sparse values over zeros.
        let uv = gather(&mut json, &mut out, 1, 3, &[1, 0], false).unwrap();
        let (bytes, accessor) = written(&json, &out, uv);
        let floats: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        assert_eq!(floats, [5.0, 6.0, 0.0, 0.0]);
        assert!(accessor.get("min").is_none());
        // Data past the view, or a sparse index past the count, are
        // refused with a reason, never a panic.
        let e = gather(&mut json, &mut out, 2, 3, &source, true).unwrap_err();
        assert!(e.contains("outside their buffer view"), "{e}");
        let e = gather(&mut json, &mut out, 3, 3, &source, true).unwrap_err();
        assert!(e.contains("outside") || e.contains("past the end"), "{e}");
        // Another count than the primitive's, or a huge offset.
        assert!(gather(&mut json, &mut out, 0, 4, &source, true).is_err());
        json["accessors"][0]["byteOffset"] = json!(u64::MAX - 3);
        assert!(gather(&mut json, &mut out, 0, 3, &source, true).is_err());
    }
}
