//! Merging every mesh instance of the scene into one character.

use std::ops::Range;

use glam::{Mat4, Vec2, Vec3};
use gltf::json::{
    self,
    mesh::{Mode, Semantic},
    validation::Checked,
};

use super::{ImportError, accessor::Accessors, document::Document};
use crate::{
    geometry::angle_weighted_normals,
    import::limits::Limits,
    rig::character::{Character, Joint, Morph, MorphTarget, Primitive, SourceStats},
    rig::skeleton::{Node, Skeleton, Transform},
};

/// Weight sums farther than this from 1 are reported (the Khronos
/// validator's tolerance for `ACCESSOR_WEIGHTS_NON_NORMALIZED` is similar).
const WEIGHT_SUM_TOLERANCE: f32 = 2e-3;

/// At most this many JOINTS_n/WEIGHTS_n sets (32 influences per vertex);
/// real rigs use 1 or 2.
const MAX_INFLUENCE_SETS: usize = 8;

fn attribute(prim: &json::mesh::Primitive, semantic: Semantic) -> Option<usize> {
    prim.attributes
        .get(&Checked::Valid(semantic))
        .map(|i| i.value())
}

fn triangles_in(mode: Mode, count: u64) -> u64 {
    match mode {
        Mode::Triangles => count / 3,
        Mode::TriangleStrip | Mode::TriangleFan => count.saturating_sub(2),
        _ => 0,
    }
}

fn mode_of(prim: &json::mesh::Primitive, path: &str) -> Result<Mode, ImportError> {
    match prim.mode {
        Checked::Valid(mode) => Ok(mode),
        Checked::Invalid => Err(ImportError::invalid(
            format!("{path}.mode"),
            "unknown primitive mode",
        )),
    }
}

/// Triangle index triples for a primitive's index list.
fn triangulate(mode: Mode, indices: &[u32]) -> Vec<[u32; 3]> {
    let n = indices.len();
    match mode {
        Mode::Triangles => indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect(),
        // Spec §3.7.2.1: strip triangle i is (p_i, p_{i+1+i%2}, p_{i+2-i%2}).
        Mode::TriangleStrip => (0..n.saturating_sub(2))
            .map(|i| [indices[i], indices[i + 1 + i % 2], indices[i + 2 - i % 2]])
            .collect(),
        // Fan triangle i is (p_{i+1}, p_{i+2}, p_0).
        Mode::TriangleFan => (0..n.saturating_sub(2))
            .map(|i| [indices[i + 1], indices[i + 2], indices[0]])
            .collect(),
        _ => Vec::new(),
    }
}

struct Builder<'a> {
    doc: &'a Document,
    acc: Accessors<'a>,
    limits: &'a Limits,
    influences: usize,
    joints: Vec<Joint>,
    skins: Vec<Option<Range<usize>>>,
    rigid: Vec<Option<usize>>,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    joint_indices: Vec<u32>,
    joint_weights: Vec<f32>,
    primitives: Vec<Primitive>,
    morphs: Vec<Morph>,
    morph_weights: Vec<Vec<f32>>,
    morph_deltas: u64,
    unnormalized: usize,
    unweighted: usize,
    zero_weight_out_of_range: usize,
    /// Normals further than the validator's tolerance from unit length.
    non_unit_normals: usize,
    /// `TEXCOORD_k` of every vertex so far, or why set k is not whole.
    uv_sets: Vec<Result<Vec<Vec2>, String>>,
    /// Whether any primitive has `TEXCOORD_k`.
    uv_seen: Vec<bool>,
}

/// The UV sets read (`TEXCOORD_0` to `TEXCOORD_3`): what a texel bake may
/// name instead of a generated atlas.
const UV_SETS: usize = 4;

pub(crate) fn build_character(
    doc: &Document,
    limits: &Limits,
) -> Result<(Character, Vec<String>), ImportError> {
    let root = &doc.root;
    let acc = Accessors::new(doc, limits);
    let instances: Vec<usize> = doc
        .scene_nodes()
        .into_iter()
        .filter(|&n| root.nodes[n].mesh.is_some())
        .collect();

    // Count what the file declares before decoding any of it.
    let (mut vertices, mut triangles, mut joint_count, mut sets) = (0u64, 0u64, 0u64, 1usize);
    let mut counted_skins = vec![false; root.skins.len()];
    for &n in &instances {
        let node = &root.nodes[n];
        let mesh = &root.meshes[node.mesh.map_or(0, |m| m.value())];
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let path = format!(
                "meshes[{}].primitives[{p}]",
                node.mesh.map_or(0, |m| m.value())
            );
            let mode = mode_of(prim, &path)?;
            let Some(pos) = attribute(prim, Semantic::Positions) else {
                continue;
            };
            let count = acc.count(pos)?;
            let index_count = match prim.indices {
                Some(i) => acc.count(i.value())?,
                None => count,
            };
            vertices = vertices.saturating_add(count);
            triangles = triangles.saturating_add(triangles_in(mode, index_count));
            if node.skin.is_some() {
                let s = (0..)
                    .take_while(|&k| {
                        attribute(prim, Semantic::Joints(k)).is_some()
                            && attribute(prim, Semantic::Weights(k)).is_some()
                    })
                    .count();
                if s > MAX_INFLUENCE_SETS {
                    return Err(ImportError::limit_at(
                        &path,
                        format!("{path}: JOINTS_n/WEIGHTS_n sets"),
                        s as u64,
                        MAX_INFLUENCE_SETS as u64,
                    ));
                }
                sets = sets.max(s);
            }
        }
        match node.skin {
            Some(s) if !std::mem::replace(&mut counted_skins[s.value()], true) => {
                joint_count += root.skins[s.value()].joints.len() as u64;
            }
            Some(_) => {}
            None => joint_count += 1,
        }
    }
    for (what, count, limit) in [
        ("vertex count", vertices, limits.max_vertices),
        ("triangle count", triangles, limits.max_triangles),
        ("joint count", joint_count, limits.max_joints),
    ] {
        if count > limit {
            return Err(ImportError::limit(what, count, limit));
        }
    }

    let mut b = Builder {
        doc,
        acc,
        limits,
        influences: 4 * sets,
        joints: Vec::new(),
        skins: vec![None; root.skins.len()],
        rigid: vec![None; root.nodes.len()],
        positions: Vec::with_capacity(vertices as usize),
        normals: Vec::with_capacity(vertices as usize),
        triangles: Vec::with_capacity(triangles as usize),
        joint_indices: Vec::new(),
        joint_weights: Vec::new(),
        primitives: Vec::new(),
        morphs: Vec::new(),
        morph_weights: vec![Vec::new(); root.nodes.len()],
        morph_deltas: 0,
        unnormalized: 0,
        unweighted: 0,
        zero_weight_out_of_range: 0,
        non_unit_normals: 0,
        uv_sets: vec![Ok(Vec::new()); UV_SETS],
        uv_seen: vec![false; UV_SETS],
    };
    let mut warnings = Vec::new();
    let mut skipped = 0usize;
    for &n in &instances {
        skipped += b.add_instance(n, &mut warnings)?;
    }
    if skipped > 0 {
        warnings.push(format!(
            "{skipped} point or line primitives ignored (AO needs triangles)"
        ));
    }
    if b.unnormalized > 0 {
        warnings.push(format!(
            "{} vertices had skin weights not summing to 1; normalised",
            b.unnormalized
        ));
    }
    if b.unweighted > 0 {
        warnings.push(format!(
            "{} vertices had all skin weights zero; bound to their first joint",
            b.unweighted
        ));
    }
    if b.zero_weight_out_of_range > 0 {
        warnings.push(format!(
            "{} joint indices past their skin had weight 0; ignored",
            b.zero_weight_out_of_range
        ));
    }
    if b.non_unit_normals > 0 {
        warnings.push(format!(
            "{} normals were not of unit length; normalised",
            b.non_unit_normals
        ));
    }
    warnings.extend(b.acc.bounds_warning());
    if b.triangles.is_empty() {
        return Err(ImportError::NoGeometry);
    }

    let skeleton = skeleton(doc, b.morph_weights, &mut warnings)?;
    let source = SourceStats {
        meshes: root.meshes.len(),
        primitives: root.meshes.iter().map(|m| m.primitives.len()).sum(),
        vertices: root
            .meshes
            .iter()
            .flat_map(|m| &m.primitives)
            .filter_map(|p| attribute(p, Semantic::Positions))
            .map(|a| b.acc.count(a).unwrap_or(0))
            .sum(),
        triangles: root
            .meshes
            .iter()
            .flat_map(|m| &m.primitives)
            .map(|p| {
                let count = match (p.indices, attribute(p, Semantic::Positions)) {
                    (Some(i), _) => b.acc.count(i.value()).unwrap_or(0),
                    (None, Some(pos)) => b.acc.count(pos).unwrap_or(0),
                    (None, None) => 0,
                };
                match p.mode {
                    Checked::Valid(mode) => triangles_in(mode, count),
                    Checked::Invalid => 0,
                }
            })
            .sum(),
        skins: root.skins.len(),
    };
    let vertex_count = b.positions.len();
    let character = Character {
        skeleton,
        joints: b.joints,
        positions: b.positions,
        normals: b.normals,
        uv_sets: uv_sets(b.uv_sets, &b.uv_seen, vertex_count),
        triangles: b.triangles,
        influences: b.influences,
        joint_indices: b.joint_indices,
        joint_weights: b.joint_weights,
        primitives: b.primitives,
        morphs: b.morphs,
        skins: b.skins,
        source,
    };
    Ok((character, warnings))
}

/// The skeleton of a document: every node with its rest transform, checked
/// to be finite.
pub(crate) fn skeleton(
    doc: &Document,
    morph_weights: Vec<Vec<f32>>,
    warnings: &mut Vec<String>,
) -> Result<Skeleton, ImportError> {
    let mut nodes = Vec::with_capacity(doc.root.nodes.len());
    // Rest rotations off unit length (NODE_ROTATION_NON_UNIT): normalised.
    let mut non_unit = 0usize;
    for ((i, node), weights) in doc.root.nodes.iter().enumerate().zip(morph_weights) {
        let rest = match node.matrix {
            Some(m) => {
                let matrix = Mat4::from_cols_array(&m);
                let t = Transform::from_matrix(matrix);
                if t.rotation.is_finite() || !matrix.is_finite() {
                    t
                } else {
                    // A zero scale on some axis (a hidden part) leaves no
                    // rotation to recover; keep translation and scale.
                    Transform {
                        translation: matrix.w_axis.truncate(),
                        rotation: glam::Quat::IDENTITY,
                        scale: Vec3::new(
                            matrix.x_axis.truncate().length(),
                            matrix.y_axis.truncate().length(),
                            matrix.z_axis.truncate().length(),
                        ),
                    }
                }
            }
            None => Transform {
                translation: node.translation.map_or(Vec3::ZERO, Vec3::from_array),
                rotation: node
                    .rotation
                    .map_or(glam::Quat::IDENTITY, |r| glam::Quat::from_array(r.0)),
                scale: node.scale.map_or(Vec3::ONE, Vec3::from_array),
            },
        };
        let finite =
            rest.translation.is_finite() && rest.rotation.is_finite() && rest.scale.is_finite();
        if !finite
            || node
                .matrix
                .is_some_and(|m| m.iter().any(|v| !v.is_finite()))
        {
            return Err(ImportError::invalid(
                format!("nodes[{i}]"),
                "transform is not finite",
            ));
        }
        if (rest.rotation.length() - 1.0).abs() > 5e-4 && node.rotation.is_some() {
            non_unit += 1;
        }
        let rest = Transform {
            rotation: rest.rotation.normalize(),
            ..rest
        };
        if !rest.rotation.is_finite() {
            return Err(ImportError::invalid(
                format!("nodes[{i}].rotation"),
                "zero quaternion",
            ));
        }
        nodes.push(Node {
            name: node.name.clone(),
            parent: doc.parents[i],
            rest,
            morph_weights: weights,
        });
    }
    if non_unit > 0 {
        warnings.push(format!(
            "{non_unit} node rotations were not unit quaternions; normalised"
        ));
    }
    Ok(Skeleton {
        nodes,
        order: doc.parents_first(),
    })
}

impl Builder<'_> {
    /// The palette range of a skin, read on first use.
    fn skin(&mut self, s: usize) -> Result<Range<usize>, ImportError> {
        if let Some(range) = &self.skins[s] {
            return Ok(range.clone());
        }
        let skin = &self.doc.root.skins[s];
        let n = skin.joints.len();
        if n == 0 {
            return Err(ImportError::invalid(
                format!("skins[{s}].joints"),
                "a skin needs at least one joint",
            ));
        }
        let matrices = match skin.inverse_bind_matrices {
            Some(a) => {
                let m = self.acc.floats(a.value(), self.limits.max_joints)?;
                if m.width != 16 || m.values.len() < 16 * n {
                    return Err(ImportError::invalid(
                        format!("skins[{s}].inverseBindMatrices"),
                        format!("needs {n} MAT4 elements, accessor {} has fewer", a.value()),
                    ));
                }
                m.values
                    .chunks_exact(16)
                    .map(Mat4::from_cols_slice)
                    .collect()
            }
            None => vec![Mat4::IDENTITY; n],
        };
        let start = self.joints.len();
        for (joint, m) in skin.joints.iter().zip(matrices) {
            self.joints.push(Joint {
                node: joint.value(),
                joint_from_bind: m,
            });
        }
        let range = start..self.joints.len();
        self.skins[s] = Some(range.clone());
        Ok(range)
    }

    fn rigid(&mut self, node: usize) -> u32 {
        *self.rigid[node].get_or_insert_with(|| {
            self.joints.push(Joint {
                node,
                joint_from_bind: Mat4::IDENTITY,
            });
            self.joints.len() - 1
        }) as u32
    }

    /// Adds one node's mesh; returns the number of primitives skipped as
    /// points or lines.
    fn add_instance(&mut self, n: usize, warnings: &mut Vec<String>) -> Result<usize, ImportError> {
        let root = &self.doc.root;
        let node = &root.nodes[n];
        let m = node.mesh.map_or(0, |m| m.value());
        let mesh = &root.meshes[m];
        let skin = node.skin.map(|s| s.value());
        let palette = match skin {
            Some(s) => self.skin(s)?,
            None => {
                let j = self.rigid(n) as usize;
                j..j + 1
            }
        };
        let mut skipped = 0;
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let path = format!("meshes[{m}].primitives[{p}]");
            let mode = mode_of(prim, &path)?;
            if !matches!(
                mode,
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                skipped += 1;
                continue;
            }
            let Some(pos) = attribute(prim, Semantic::Positions) else {
                warnings.push(format!("{path} has no POSITION; skipped"));
                continue;
            };
            let positions = self.acc.floats(pos, self.limits.max_vertices)?;
            if positions.width != 3 {
                return Err(ImportError::invalid(
                    format!("{path}.attributes.POSITION"),
                    "must be VEC3",
                ));
            }
            let positions = positions.vec3();
            let count = positions.len();
            let base = self.positions.len();
            let indices = match prim.indices {
                Some(i) => {
                    let idx = self
                        .acc
                        .uints(i.value(), self.limits.max_triangles.saturating_mul(3))?;
                    if idx.width != 1 {
                        return Err(ImportError::invalid(
                            format!("{path}.indices"),
                            "must be SCALAR",
                        ));
                    }
                    if let Some((k, v)) = idx
                        .values
                        .iter()
                        .enumerate()
                        .find(|(_, v)| **v as usize >= count)
                    {
                        return Err(ImportError::invalid(
                            format!("{path}.indices"),
                            format!(
                                "index {k} (accessor {}) is {v}, but POSITION has {count} vertices",
                                i.value()
                            ),
                        ));
                    }
                    idx.values
                }
                None => (0..count as u32).collect(),
            };
            let triangles = triangulate(mode, &indices);
            let normals = match attribute(prim, Semantic::Normals) {
                Some(a) => {
                    Some(self.vec3_attribute(a, count, &format!("{path}.attributes.NORMAL"))?)
                }
                None => None,
            };
            // Quantized normals (normalized bytes or shorts) are as unit
            // as their precision allows; only float ones are judged.
            let float_normals = attribute(prim, Semantic::Normals).is_some_and(|a| {
                matches!(
                    self.acc.root.accessors.get(a).map(|x| x.component_type),
                    Some(Checked::Valid(json::accessor::GenericComponentType(
                        json::accessor::ComponentType::F32
                    )))
                )
            });
            let morph = self.morph_targets(prim, n, m, count, &path)?;

            let tri_start = self.triangles.len();
            self.triangles
                .extend(triangles.iter().map(|t| t.map(|i| i + base as u32)));
            self.positions.extend_from_slice(&positions);
            self.read_uv_sets(prim, count, &path);
            let computed_normals = normals.is_none();
            match normals {
                Some(normals) => {
                    // ACCESSOR_VECTOR3_NON_UNIT's tolerance.
                    if float_normals {
                        self.non_unit_normals += normals
                            .iter()
                            .filter(|n| (n.length() - 1.0).abs() > 5e-4)
                            .count();
                    }
                    self.normals
                        .extend(normals.into_iter().map(Vec3::normalize_or_zero));
                }
                None => {
                    self.normals.resize(base + count, Vec3::ZERO);
                    angle_weighted_normals(
                        &self.positions,
                        &self.triangles[tri_start..],
                        base..base + count,
                        &mut self.normals,
                    );
                }
            }
            match skin {
                Some(s) => self.skin_weights(prim, count, palette.clone(), s, &path)?,
                None => {
                    for _ in 0..count {
                        self.joint_indices.push(palette.start as u32);
                        self.joint_weights.push(1.0);
                        for _ in 1..self.influences {
                            self.joint_indices.push(palette.start as u32);
                            self.joint_weights.push(0.0);
                        }
                    }
                }
            }
            if let Some(targets) = morph {
                self.morphs.push(Morph {
                    node: n,
                    vertices: base..base + count,
                    targets,
                });
            }
            self.primitives.push(Primitive {
                node: n,
                mesh: m,
                primitive: p,
                skin,
                vertices: base..base + count,
                triangles: tri_start..self.triangles.len(),
                computed_normals,
            });
        }
        Ok(skipped)
    }

    /// Appends each UV set of a primitive's `count` vertices, or records
    /// why the set is not whole. Leniently: an unreadable or missing set
    /// fails only a bake that names it, never the import.
    fn read_uv_sets(&mut self, prim: &json::mesh::Primitive, count: usize, path: &str) {
        for (k, set) in self.uv_sets.iter_mut().enumerate() {
            let attr = attribute(prim, Semantic::TexCoords(k as u32));
            self.uv_seen[k] |= attr.is_some();
            let Ok(uvs) = set else { continue };
            let read = match attr {
                None => Err(format!("{path} has no TEXCOORD_{k}")),
                Some(a) => match self.acc.floats(a, count as u64) {
                    Ok(d) if d.width == 2 && d.values.len() == 2 * count => Ok(d.values),
                    Ok(_) => Err(format!(
                        "{path}.attributes.TEXCOORD_{k} (accessor {a}) must be VEC2 with {count} elements, like POSITION"
                    )),
                    Err(e) => Err(format!("{path}.attributes.TEXCOORD_{k}: {e}")),
                },
            };
            match read {
                Ok(values) => uvs.extend(values.chunks_exact(2).map(|c| Vec2::new(c[0], c[1]))),
                Err(why) => *set = Err(why),
            }
        }
    }

    fn vec3_attribute(
        &self,
        accessor: usize,
        count: usize,
        path: &str,
    ) -> Result<Vec<Vec3>, ImportError> {
        let data = self.acc.floats(accessor, count as u64)?;
        if data.width != 3 || data.values.len() != 3 * count {
            return Err(ImportError::invalid(
                path,
                format!("accessor {accessor} must be VEC3 with {count} elements, like POSITION"),
            ));
        }
        Ok(data.vec3())
    }

    fn morph_targets(
        &mut self,
        prim: &json::mesh::Primitive,
        n: usize,
        m: usize,
        count: usize,
        path: &str,
    ) -> Result<Option<Vec<MorphTarget>>, ImportError> {
        let Some(targets) = prim.targets.as_ref().filter(|t| !t.is_empty()) else {
            return Ok(None);
        };
        if targets.len() as u64 > self.limits.max_morph_targets {
            return Err(ImportError::limit_at(
                format!("{path}.targets"),
                format!("{path}.targets count"),
                targets.len() as u64,
                self.limits.max_morph_targets,
            ));
        }
        let deltas = (count as u64).saturating_mul(targets.len() as u64);
        self.morph_deltas = self.morph_deltas.saturating_add(deltas);
        if self.morph_deltas > self.limits.max_morph_deltas {
            return Err(ImportError::limit(
                "morph-target vertices (vertices × targets)",
                self.morph_deltas,
                self.limits.max_morph_deltas,
            ));
        }
        let mut out = Vec::with_capacity(targets.len());
        for (t, target) in targets.iter().enumerate() {
            let tpath = format!("{path}.targets[{t}]");
            let positions = match target.positions {
                Some(a) => self.vec3_attribute(a.value(), count, &format!("{tpath}.POSITION"))?,
                None => vec![Vec3::ZERO; count],
            };
            let normals = match target.normals {
                Some(a) => {
                    Some(self.vec3_attribute(a.value(), count, &format!("{tpath}.NORMAL"))?)
                }
                None => None,
            };
            out.push(MorphTarget { positions, normals });
        }
        let node = &self.doc.root.nodes[n];
        let defaults = node
            .weights
            .clone()
            .or_else(|| self.doc.root.meshes[m].weights.clone())
            .unwrap_or_else(|| vec![0.0; targets.len()]);
        if defaults.len() != targets.len() || defaults.iter().any(|w| !w.is_finite()) {
            return Err(ImportError::invalid(
                format!("meshes[{m}].weights"),
                format!(
                    "needs {} finite weights, one per morph target",
                    targets.len()
                ),
            ));
        }
        let current = &mut self.morph_weights[n];
        if !current.is_empty() && current.len() != defaults.len() {
            return Err(ImportError::invalid(
                path,
                "every primitive of a mesh must have the same number of morph targets",
            ));
        }
        *current = defaults;
        Ok(Some(out))
    }

    fn skin_weights(
        &mut self,
        prim: &json::mesh::Primitive,
        count: usize,
        palette: Range<usize>,
        skin: usize,
        path: &str,
    ) -> Result<(), ImportError> {
        let k = self.influences;
        let skin_joints = palette.len();
        let mut joints = vec![0u32; count * k];
        let mut weights = vec![0f32; count * k];
        let mut sets = 0;
        for set in 0..(k / 4) as u32 {
            let (Some(ja), Some(wa)) = (
                attribute(prim, Semantic::Joints(set)),
                attribute(prim, Semantic::Weights(set)),
            ) else {
                break;
            };
            let (jpath, wpath) = (
                format!("{path}.attributes.JOINTS_{set}"),
                format!("{path}.attributes.WEIGHTS_{set}"),
            );
            let j = self.acc.uints(ja, count as u64)?;
            let w = self.acc.floats(wa, count as u64)?;
            if j.width != 4 || j.values.len() != 4 * count {
                return Err(ImportError::invalid(
                    jpath,
                    format!("accessor {ja} must be VEC4 with {count} elements"),
                ));
            }
            if w.width != 4 || w.values.len() != 4 * count {
                return Err(ImportError::invalid(
                    wpath,
                    format!("accessor {wa} must be VEC4 with {count} elements"),
                ));
            }
            for v in 0..count {
                for c in 0..4 {
                    let (ji, wi) = (j.values[v * 4 + c], w.values[v * 4 + c]);
                    if wi < -1e-6 {
                        return Err(ImportError::invalid(
                            &wpath,
                            format!("vertex {v} has negative weight {wi}"),
                        ));
                    }
                    let slot = v * k + set as usize * 4 + c;
                    if ji as usize >= skin_joints {
                        if wi > 0.0 {
                            return Err(ImportError::invalid(
                                &jpath,
                                format!(
                                    "vertex {v} uses joint {ji} (accessor {ja}), but skin {skin} has {skin_joints} joints"
                                ),
                            ));
                        }
                        self.zero_weight_out_of_range += 1;
                        continue;
                    }
                    joints[slot] = ji;
                    weights[slot] = wi.max(0.0);
                }
            }
            sets += 1;
        }
        if sets == 0 {
            return Err(ImportError::invalid(
                path,
                format!(
                    "the mesh is skinned (skin {skin}) but the primitive has no JOINTS_0/WEIGHTS_0"
                ),
            ));
        }
        for v in 0..count {
            let w = &mut weights[v * k..(v + 1) * k];
            let sum: f32 = w.iter().sum();
            if sum <= 1e-12 {
                self.unweighted += 1;
                w[0] = 1.0;
                continue;
            }
            if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
                self.unnormalized += 1;
            }
            w.iter_mut().for_each(|x| *x /= sum);
        }
        self.joint_indices.extend(
            joints
                .into_iter()
                .map(|j| (palette.start + j as usize) as u32),
        );
        self.joint_weights.extend(weights);
        Ok(())
    }
}

/// The UV sets of a merged mesh of `vertices` vertices, up to the last
/// that some primitive has (`seen`).
fn uv_sets(
    sets: Vec<Result<Vec<Vec2>, String>>,
    seen: &[bool],
    vertices: usize,
) -> Vec<Result<Vec<Vec2>, String>> {
    let keep = seen.iter().rposition(|&s| s).map_or(0, |k| k + 1);
    sets.into_iter()
        .take(keep)
        .map(|set| {
            set.and_then(|uvs| {
                if uvs.len() == vertices {
                    Ok(uvs)
                } else {
                    Err(format!(
                        "it covers {} of the {vertices} vertices",
                        uvs.len()
                    ))
                }
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_become_lists_with_consistent_winding() {
        assert_eq!(
            triangulate(Mode::TriangleStrip, &[0, 1, 2, 3, 4]),
            vec![[0, 1, 2], [1, 3, 2], [2, 3, 4]]
        );
        assert_eq!(
            triangulate(Mode::TriangleFan, &[0, 1, 2, 3]),
            vec![[1, 2, 0], [2, 3, 0]]
        );
        assert_eq!(triangulate(Mode::Triangles, &[0, 1, 2, 3]), vec![[0, 1, 2]]);
        assert!(triangulate(Mode::TriangleStrip, &[0, 1]).is_empty());
    }
}
