//! A character with its baked AO as glTF (`aobake export ASSET FILE --gltf
//! OUT.glb`): the character's own file, rewritten as one GLB, with the AO
//! as vertex data an engine loads the way it loads morph targets.
//!
//! Per primitive of the mesh aobake baked (in aobake's vertex order,
//! `Character::primitives`):
//!
//! * `_AO` (FLOAT SCALAR): the model's AO averaged over the frames of the
//!   file's clips at 30 fps (the rest pose without clips); a static AO an
//!   engine can use as it is;
//! * `COLOR_0` (FLOAT VEC3): `1 − _AO` as grey, for viewers that show only
//!   colours (the next free `COLOR_n` when the primitive has one);
//! * for vertex-linear and vertex-clustered, `_AO_BASIS_0`, `_AO_BASIS_1`,
//!   … (FLOAT VEC4): the model's coefficient rows at the vertex, four a
//!   attribute (row `j` in component `j mod 4` of `_AO_BASIS_{j div 4}`,
//!   zero past the last), so that per pose
//!   `ao(v) = clamp(Σ_j w_j · row_j(v), 0, 1)`.
//!
//! `extras.aobake.primitives` lists the primitives in aobake's vertex
//! order (`node`, `mesh`, `primitive`, `first`, `count`), so that vertex
//! `first + i` of the asset is vertex `i` of that primitive.
//!
//! The weights `w` of a pose are the asset's per-pose step
//! (`docs/asset-format.md`), whose numbers the root's `extras.aobake`
//! carries: the asset header's `layout` (node indices are the glTF file's
//! node indices) and its small sections (`NORM`, `PROJ`, `BMIX`, `CENT`,
//! `AXES`, `BNRM`, `BPRJ`) as arrays of numbers (`docs/engines.md`).
//!
//! A texel asset ([`texel`]) is exported over its atlas instead: each
//! primitive is re-indexed over the atlas's vertices (split where charts
//! meet) and gains the atlas as its next free `TEXCOORD_n`, its material
//! the static AO as the standard `occlusionTexture`, and `extras.aobake`
//! the basis textures as 16-bit images.
//!
//! Everything else in the file is kept: buffers are merged into the one
//! GLB buffer (views moved accordingly), images given by URI are embedded,
//! and a mesh that several nodes instance is copied per extra instance,
//! since each instance has its own AO.

mod glb;
mod texel;

use glb::{Glb, Specific, array, existing};

use serde_json::{Map, Value, json};

use crate::{
    Limits,
    asset::{AssetError, Container, Data},
    import::{ImportError, Upload, import_with_source},
    method::{
        Family,
        texel::TexelModel,
        vertex::{AssetHeader, FormRef, Model, check_character},
    },
    rig::{
        clip::{Clip, Interpolation, Property},
        pose::Pose,
    },
};

/// Most coefficient rows an export stores as vertex attributes (16 VEC4).
pub const MAX_ROWS: usize = 64;

/// Most clip frames the static `_AO` averages (spread evenly over all).
const MAX_FRAMES: usize = 4096;

/// The frame rate the static `_AO` samples clips at.
const FPS: f32 = 30.0;

/// Why an export could not be made.
#[derive(Debug, thiserror::Error)]
pub enum GltfExportError {
    /// The character file.
    #[error("the character: {0}")]
    Import(#[from] ImportError),
    /// The asset.
    #[error("the asset: {0}")]
    Asset(#[from] AssetError),
    /// The asset and the character do not go together, or the asset has no
    /// per-vertex data.
    #[error("{0}")]
    Unsupported(String),
}

/// A written export.
#[derive(Debug, Clone)]
pub struct GltfExport {
    /// The GLB file.
    pub glb: Vec<u8>,
    /// Things kept as they were that deserve a look.
    pub warnings: Vec<String>,
    /// Coefficient rows per vertex (0 for a static average).
    pub rows: usize,
    /// Clip frames the static `_AO` averages.
    pub frames: usize,
    /// What was written, as a person reads it.
    pub summary: String,
}

/// Exports `upload` (the character the asset was baked for) with the AO of
/// `asset` (a vertex method's); the static `_AO` averages the frames of
/// the character's clips and of `clips` (a second file's animations,
/// bound by node name, as a bake takes them).
pub fn export_gltf(
    upload: Upload<'_>,
    clips: Option<Upload<'_>>,
    limits: &Limits,
    asset: &Container,
) -> Result<GltfExport, GltfExportError> {
    let family = asset.method.family();
    if !matches!(family, Family::Vertex | Family::Texel) {
        return Err(GltfExportError::Unsupported(format!(
            "a {} asset has no per-vertex or texture-space AO to put in a glTF file (its data exports with --exr)",
            asset.method.name()
        )));
    }
    let source = import_with_source(upload, limits)?;
    let character = &source.imported.character;
    let v = character.vertex_count();
    // A texel asset's model is over its atlas's texels.
    let (texel, header): (Option<TexelModel>, AssetHeader) = match family {
        Family::Texel => {
            let (m, header) = crate::bake::texel::read(asset, Some(character))
                .map_err(|e| GltfExportError::Unsupported(e.to_string()))?;
            (Some(m), header)
        }
        _ => (None, Model::from_container(asset)?.1),
    };
    let vertex_model = match &texel {
        Some(_) => None,
        None => {
            let (model, _) = Model::from_container(asset)?;
            check_character(&model, character).map_err(GltfExportError::Unsupported)?;
            Some(model)
        }
    };
    let model = match (&texel, &vertex_model) {
        (Some(t), _) => &t.model,
        (None, Some(m)) => m,
        (None, None) => unreachable!("one of the two is read"),
    };

    let imported = &source.imported;
    let mut all_clips = imported.clips.clone();
    let mut warnings = Vec::new();
    // The second file's clips, bound to the character's nodes: written
    // into the file as animations too (but those the character's file
    // has already, as when it is given as its own clips).
    let mut added_clips = Vec::new();
    if let Some(clips) = clips {
        let (more, clip_warnings) = crate::import_clips(clips, character, limits)
            .map_err(|e| GltfExportError::Unsupported(format!("the clips: {e}")))?;
        added_clips = more
            .iter()
            .filter(|c| !imported.clips.contains(c))
            .cloned()
            .collect();
        all_clips.extend(more);
        warnings.extend(clip_warnings);
    }
    let (static_ao, frames) = static_ao(model, &imported.character.skeleton, &all_clips);
    if frames == 0 {
        warnings.push(
            "no clips: the static AO is the AO at rest (give the clips the asset was baked with, --clips)"
                .to_owned(),
        );
    }

    let mut out = Glb::default();
    let mut json = source.json;
    // Every buffer into the one: views move by their buffer's offset.
    let bases: Vec<usize> = source.buffers.iter().map(|b| out.append(b)).collect();
    for view in existing(&mut json, "bufferViews") {
        let buffer = view["buffer"].as_u64().unwrap_or(0) as usize;
        let offset = view["byteOffset"].as_u64().unwrap_or(0) as usize;
        view["buffer"] = 0.into();
        view["byteOffset"] = (bases.get(buffer).copied().unwrap_or(0) + offset).into();
    }
    // Images given by URI: embedded, where the upload has them.
    let views_before = existing(&mut json, "bufferViews").len();
    let mut new_views = Vec::new();
    for (i, image) in existing(&mut json, "images").iter_mut().enumerate() {
        if image.get("uri").is_none() {
            continue;
        }
        let bytes = match source.images.get(i).cloned().flatten() {
            Some(bytes) => bytes,
            None => {
                // The GLB must stand alone: a white pixel holds the place
                // (textures keep their indices).
                warnings.push(format!(
                    "images[{i}]: {} was not given beside the file: a 1×1 white PNG stands in",
                    image["uri"]
                ));
                image["mimeType"] = "image/png".into();
                crate::image::encode_rgb_png(&[255, 255, 255], 1, 1).expect("a 1×1 PNG encodes")
            }
        };
        let mime = image["mimeType"]
            .as_str()
            .map(str::to_owned)
            .or_else(|| sniff_mime(&bytes).map(str::to_owned));
        let Some(mime) = mime else {
            warnings.push(format!("images[{i}]: neither PNG nor JPEG, its uri kept"));
            continue;
        };
        let offset = out.append(&bytes);
        let object = image.as_object_mut().expect("images are objects");
        object.remove("uri");
        object.insert("mimeType".into(), mime.into());
        object.insert("bufferView".into(), (views_before + new_views.len()).into());
        new_views.push(json!({ "buffer": 0, "byteOffset": offset, "byteLength": bytes.len() }));
    }
    if !new_views.is_empty() {
        array(&mut json, "bufferViews").extend(new_views);
    }

    // Each node that instances a mesh gets its own copy after the first.
    let mut mesh_of_node = std::collections::BTreeMap::<usize, usize>::new();
    let mut first_node_of_mesh = std::collections::BTreeMap::<usize, usize>::new();
    for p in &character.primitives {
        if mesh_of_node.contains_key(&p.node) {
            continue;
        }
        let mesh = match first_node_of_mesh.get(&p.mesh) {
            None => {
                first_node_of_mesh.insert(p.mesh, p.node);
                p.mesh
            }
            Some(_) => {
                let meshes = array(&mut json, "meshes");
                let copy = meshes[p.mesh].clone();
                meshes.push(copy);
                let index = meshes.len() - 1;
                array(&mut json, "nodes")[p.node]["mesh"] = index.into();
                index
            }
        };
        mesh_of_node.insert(p.node, mesh);
    }

    let specific = match &texel {
        Some(t) => texel::write(
            &mut json,
            &mut out,
            character,
            &mesh_of_node,
            t,
            &static_ao,
            frames,
            &mut warnings,
        )
        .map_err(GltfExportError::Unsupported)?,
        None => vertex_attributes(
            &mut json,
            &mut out,
            character,
            &mesh_of_node,
            model,
            &static_ao,
            frames,
        )?,
    };
    for clip in &added_clips {
        write_animation(&mut json, &mut out, clip);
    }

    let sections: Map<String, Value> = asset
        .sections
        .iter()
        .filter(|s| {
            [
                b"NORM", b"PROJ", b"BMIX", b"CENT", b"AXES", b"BNRM", b"BPRJ",
            ]
            .contains(&&s.tag)
        })
        .filter_map(|s| match &s.data {
            Data::F32(values) => Some((
                String::from_utf8_lossy(&s.tag).into_owned(),
                Value::from(values.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>()),
            )),
            _ => None,
        })
        .collect();
    let mut aobake = json!({
        "version": 1,
        "method": header.method,
        "format": format!("{}.{}", asset.version.0, asset.version.1),
        "algorithm_version": header.algorithm_version,
        "bake_key": header.bake_key,
        "character": header.character,
        "vertices": v,
        "layout": serde_json::to_value(&header.layout).expect("layouts serialise"),
        "sections": sections,
    });
    let fields = aobake.as_object_mut().expect("an object");
    fields.extend(specific.extras);
    let root = json.as_object_mut().expect("a glTF root is an object");
    match root.entry("extras") {
        serde_json::map::Entry::Occupied(mut e) => match e.get_mut().as_object_mut() {
            Some(extras) => {
                extras.insert("aobake".into(), aobake);
            }
            None => {
                warnings.push("the file's root extras were not an object: replaced".into());
                e.insert(json!({ "aobake": aobake }));
            }
        },
        serde_json::map::Entry::Vacant(e) => {
            e.insert(json!({ "aobake": aobake }));
        }
    }
    root.insert("buffers".into(), json!([{ "byteLength": out.bin.len() }]));
    Ok(GltfExport {
        glb: out.finish(&json),
        warnings,
        rows: specific.rows,
        frames,
        summary: specific.summary,
    })
}

/// A vertex asset's attributes on every primitive: `_AO`, its grey
/// `COLOR_n` and the `_AO_BASIS_k` rows.
fn vertex_attributes(
    json: &mut Value,
    out: &mut Glb,
    character: &crate::Character,
    mesh_of_node: &std::collections::BTreeMap<usize, usize>,
    model: &Model,
    static_ao: &[f32],
    frames: usize,
) -> Result<Specific, GltfExportError> {
    let (rows, coefficients) = match model {
        Model::StaticAverage(_) => (0, Vec::new()),
        _ => rows_per_vertex(model)?,
    };
    let attributes_per_vertex = rows.div_ceil(4);
    let mut color_names = Vec::new();
    let mut order = Vec::new();
    for p in &character.primitives {
        let mesh = mesh_of_node[&p.node];
        let count = p.vertices.len();
        let position = json["meshes"][mesh]["primitives"][p.primitive]["attributes"]["POSITION"]
            .as_u64()
            .and_then(|a| json["accessors"][a as usize]["count"].as_u64());
        if position != Some(count as u64) {
            return Err(GltfExportError::Unsupported(format!(
                "meshes[{}].primitives[{}]: {count} vertices in aobake's order but POSITION has {position:?}",
                p.mesh, p.primitive
            )));
        }
        let vertices = p.vertices.clone();
        order.push(json!({
            "node": p.node,
            "mesh": mesh,
            "source_mesh": p.mesh,
            "primitive": p.primitive,
            "first": vertices.start,
            "count": count,
        }));
        let ao: Vec<f32> = static_ao[vertices.clone()].to_vec();
        let grey: Vec<f32> = ao.iter().flat_map(|&a| [1.0 - a; 3]).collect();
        let mut added = vec![("_AO".to_owned(), out.accessor(json, &ao, "SCALAR"))];
        let attributes = json["meshes"][mesh]["primitives"][p.primitive]["attributes"]
            .as_object()
            .cloned()
            .unwrap_or_default();
        let color = (0..)
            .map(|n| format!("COLOR_{n}"))
            .find(|name| !attributes.contains_key(name))
            .expect("a free COLOR_n");
        color_names.push(color.clone());
        added.push((color, out.accessor(json, &grey, "VEC3")));
        let width = 4 * attributes_per_vertex;
        for k in 0..attributes_per_vertex {
            let values: Vec<f32> = vertices
                .clone()
                .flat_map(|v| coefficients[v * width + 4 * k..v * width + 4 * k + 4].to_vec())
                .collect();
            added.push((
                format!("_AO_BASIS_{k}"),
                out.accessor(json, &values, "VEC4"),
            ));
        }
        let target = &mut json["meshes"][mesh]["primitives"][p.primitive]["attributes"];
        for (name, accessor) in added {
            target[name.as_str()] = accessor.into();
        }
    }
    color_names.sort();
    color_names.dedup();
    let extras = json!({
        "primitives": order,
        "static": { "attribute": "_AO", "color": color_names, "frames": frames },
        "rows": rows,
        "basis": (0..attributes_per_vertex).map(|k| format!("_AO_BASIS_{k}")).collect::<Vec<_>>(),
    });
    Ok(Specific {
        extras: extras.as_object().cloned().unwrap_or_default(),
        rows,
        summary: format!(
            "_AO over {frames} clip frames, COLOR_0, {rows} coefficient rows in {attributes_per_vertex} _AO_BASIS attributes"
        ),
    })
}

/// Writes `clip` into the file as an animation, its keys into `out`: a
/// second file's clip, already bound to the character's nodes (a
/// skeleton's node index is the file's).
fn write_animation(json: &mut Value, out: &mut Glb, clip: &Clip) {
    let mut channels = Vec::with_capacity(clip.channels.len());
    let mut samplers = Vec::with_capacity(clip.channels.len());
    for c in &clip.channels {
        let input = out.data_accessor(json, &c.times, "SCALAR", None);
        // Animation inputs must state their bounds.
        let (lo, hi) = c
            .times
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &t| {
                (lo.min(t), hi.max(t))
            });
        json["accessors"][input]["min"] = json!([lo]);
        json["accessors"][input]["max"] = json!([hi]);
        let (kind, path) = match c.property {
            Property::Translation => ("VEC3", "translation"),
            Property::Rotation => ("VEC4", "rotation"),
            Property::Scale => ("VEC3", "scale"),
            Property::Weights => ("SCALAR", "weights"),
        };
        let output = out.data_accessor(json, &c.values, kind, None);
        samplers.push(json!({
            "input": input,
            "output": output,
            "interpolation": match c.interpolation {
                Interpolation::Step => "STEP",
                Interpolation::Linear => "LINEAR",
                Interpolation::CubicSpline => "CUBICSPLINE",
            },
        }));
        channels.push(json!({
            "sampler": samplers.len() - 1,
            "target": { "node": c.node, "path": path },
        }));
    }
    array(json, "animations").push(json!({
        "name": clip.name,
        "channels": channels,
        "samplers": samplers,
    }));
}

/// The model's AO averaged over the clips' frames at [`FPS`] (at most
/// [`MAX_FRAMES`], spread evenly), or at rest without clips; and the frame
/// count.
pub(crate) fn static_ao(
    model: &Model,
    skeleton: &crate::rig::skeleton::Skeleton,
    clips: &[crate::rig::clip::Clip],
) -> (Vec<f32>, usize) {
    let mut poses: Vec<(usize, f32)> = clips
        .iter()
        .enumerate()
        .flat_map(|(c, clip)| clip.frame_times(FPS).into_iter().map(move |t| (c, t)))
        .collect();
    if poses.len() > MAX_FRAMES {
        let step = poses.len() as f64 / MAX_FRAMES as f64;
        poses = (0..MAX_FRAMES)
            .map(|i| poses[(i as f64 * step) as usize])
            .collect();
    }
    let locals: Vec<Vec<crate::rig::skeleton::Transform>> = if poses.is_empty() {
        vec![skeleton.rest_locals()]
    } else {
        poses
            .iter()
            .map(|&(c, t)| Pose::sample(skeleton, &clips[c], t).locals)
            .collect()
    };
    let mut sum = vec![0.0f64; model.vertices()];
    for l in &locals {
        for (s, a) in sum.iter_mut().zip(model.evaluate(skeleton, l)) {
            *s += f64::from(a);
        }
    }
    let n = locals.len() as f64;
    (sum.iter().map(|&s| (s / n) as f32).collect(), poses.len())
}

/// Every vertex's coefficient rows, `4 · ceil(R / 4)` floats a vertex (zero
/// past row R), and R.
fn rows_per_vertex(model: &Model) -> Result<(usize, Vec<f32>), GltfExportError> {
    let v = model.vertices();
    let rows = model.weight_count();
    if rows > MAX_ROWS {
        let fix = match model {
            Model::VertexClustered(..) => {
                "an eigen-AO basis of the whole model (`--param clustered.basis_cv=false \
                 --param clustered.basis=32`: 33 rows; cross-validation keeps a basis only \
                 where it saves multiply-adds, and the linear base and every pose cluster \
                 otherwise each add their rows)"
            }
            _ => {
                "an eigen-AO basis (`--param linear.basis_cv=false`: `linear.basis` rows, 32 by default)"
            }
        };
        return Err(GltfExportError::Unsupported(format!(
            "the model takes {rows} weights per pose, more than the {MAX_ROWS} rows a glTF export \
             stores as vertex attributes: bake it with {fix}"
        )));
    }
    let width = 4 * rows.div_ceil(4);
    let mut out = vec![0.0f32; v * width];
    match model.form() {
        FormRef::Dense(f) => {
            let mut row = 0;
            for block in &f.blocks {
                for k in 0..block.rows {
                    let coefficients =
                        &block.coefficients[k * block.columns..(k + 1) * block.columns];
                    for vertex in 0..v {
                        let column = block.map.as_ref().map_or(vertex, |m| m[vertex] as usize);
                        out[vertex * width + row] = coefficients[column].to_f32();
                    }
                    row += 1;
                }
            }
        }
        FormRef::Sparse(s) => {
            for vertex in 0..v {
                let (from, to) = (s.offsets[vertex] as usize, s.offsets[vertex + 1] as usize);
                for e in from..to {
                    out[vertex * width + usize::from(s.rows_of[e])] = s.values[e].to_f32();
                }
            }
        }
    }
    Ok((rows, out))
}

fn sniff_mime(bytes: &[u8]) -> Option<&'static str> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        Some("image/png")
    } else if bytes.starts_with(&[0xFF, 0xD8, 0xFF]) {
        Some("image/jpeg")
    } else {
        None
    }
}
