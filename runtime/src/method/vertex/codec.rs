//! The per-vertex methods in the asset container: the JSON header's
//! [`Layout`] says what each section means, [`Model::to_container`]
//! writes them and [`Model::from_container`] reads them back, checking
//! every length and number against the header (and, from format 1.4,
//! every node against the rig the header carries) so that a hostile file
//! with valid checksums is refused with a message.

use half::f16;
use serde::{Deserialize, Serialize};

use super::{
    ALGORITHM_VERSION, Basis, Block, Centering, Coefficients, Features, LinearBase, LinearForm,
    Model, PoseCluster, SparseForm, StaticAverage, VertexClustered, VertexLinear, form,
};
use crate::container::check_primitives;
pub use crate::container::{AssetHeaderFields, PrimitiveSpan};
use crate::{
    Method,
    container::{AssetError, Container, Data, Section},
    pose_space::{Handles, JointAngles},
    rig::Skeleton,
};

/// The model's structure in the asset header: what the sections mean.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum Layout {
    /// `COEF`: V means.
    StaticAverage,
    /// `COEF`: `(N+1) × V` row-major, or with `sparse` the CSR values
    /// (`CSRO` offsets, `CSRR` rows); `NORM`: the N angle means, then the N
    /// inverse standard deviations.
    VertexLinear {
        /// The joint-angle parameters (N), their nodes and ranges.
        joint_angles: JointAngles,
        /// Whether coefficients are sparse.
        sparse: bool,
        /// What the model is linear in (absent in assets written before
        /// there was a choice: rotation vectors).
        #[serde(default)]
        features: Features,
        /// With a projection (`PROJ`: `components × features` f32,
        /// row-major): the principal directions the model is linear in;
        /// 0: none, the model is linear in the features.
        #[serde(default)]
        components: usize,
        /// Eigen-AO basis rows (`BMIX`: the `(N+1) × basis` mix, row-major,
        /// then `basis` offsets, f32); `COEF` is then `(basis+1) × V`, or
        /// with `sparse` the CSR of those rows. 0: none.
        #[serde(default, skip_serializing_if = "is_zero")]
        basis: usize,
    },
    /// `COEF`: the mean block then one block per pose cluster;
    /// `CENT`: `m × H` centres; `AXES`: `m × n × H` projections; `VMAP`:
    /// the vertex-cluster maps of the blocks that have one, concatenated.
    VertexClustered {
        /// The handle layout (H = 6 × joints).
        handles: Handles,
        /// n.
        dimensions: usize,
        /// α.
        alpha: f32,
        /// Centring.
        centering: Centering,
        /// Clamp of the whitened coordinates (0: none).
        clamp: f32,
        /// Columns of each pose cluster's block (V when unmapped).
        columns: Vec<usize>,
        /// A vertex-linear base (`BNRM`, `BPRJ` as vertex-linear's `NORM`
        /// and `PROJ`): block 0 of `COEF` is then its coefficients, a row
        /// per weight, instead of the mean.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        base: Option<BaseLayout>,
        /// Eigen-AO basis rows (`BMIX` as vertex-linear's, its inputs the
        /// weights of every block above); `COEF` is then one `(basis+1) ×
        /// V` block, and there is no `VMAP`. 0: none.
        #[serde(default, skip_serializing_if = "is_zero")]
        basis: usize,
        /// With a basis: its rows stored sparse (`COEF`, `CSRO`, `CSRR` as
        /// vertex-linear's), small entries dropped.
        #[serde(default, skip_serializing_if = "is_false")]
        sparse: bool,
    },
}

fn is_false(x: &bool) -> bool {
    !*x
}

fn is_zero(x: &usize) -> bool {
    *x == 0
}

/// vertex-clustered's linear base in the header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BaseLayout {
    /// The joint angles it reads.
    pub joint_angles: JointAngles,
    /// Its features.
    pub features: Features,
    /// Its principal directions (0: none).
    pub components: usize,
}

/// The asset's JSON header (DESIGN §7).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AssetHeader {
    /// The program that wrote it.
    pub generator: String,
    /// The method.
    pub method: Method,
    /// [`ALGORITHM_VERSION`] of the writer.
    pub algorithm_version: u32,
    /// sha256 of the bake's canonical request (inputs, method, params,
    /// algorithm version).
    pub bake_key: String,
    /// sha256 of the character upload.
    pub character: String,
    /// sha256 of each clip upload (empty when the clips came with the
    /// character).
    pub clips: Vec<String>,
    /// Vertices, in aobake's vertex order.
    pub vertices: usize,
    /// What the values mean.
    pub units: String,
    /// The bake's fully defaulted parameters.
    pub params: serde_json::Value,
    /// The model's structure.
    pub layout: Layout,
    /// The character's node hierarchy (names, parents, rest transforms)
    /// that the layout's node indices point into: what an engine poses by
    /// node name. Absent in assets written before format 1.4.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rig: Option<Skeleton>,
    /// Where each glTF primitive's vertices are (format 1.6; empty
    /// before).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub primitives: Vec<PrimitiveSpan>,
}

/// What the stored values mean, written into every header.
pub const UNITS: &str = "occlusion per vertex: 0 = open, 1 = blocked";

impl Model {
    /// The asset: header and sections, with the `skeleton` the model reads
    /// as its rig.
    pub fn to_container(&self, header: AssetHeaderFields, skeleton: &Skeleton) -> Container {
        self.to_container_as(self.method(), UNITS, header, skeleton)
    }

    /// [`Model::to_container`] under another method's name and units: a
    /// texel method's model is a vertex method's over texels
    /// (`super::super::texel`).
    pub(crate) fn to_container_as(
        &self,
        method: Method,
        units: &str,
        header: AssetHeaderFields,
        skeleton: &Skeleton,
    ) -> Container {
        let (layout, sections) = match self {
            Self::StaticAverage(m) => (Layout::StaticAverage, form_sections(&m.form)),
            Self::VertexLinear(joint_angles, m) => {
                let (sparse, mut sections) = coefficient_sections(&m.coefficients);
                sections.extend(linear_weight_sections(m, LINEAR_TAGS));
                sections.extend(m.basis.as_ref().map(basis_section));
                (
                    Layout::VertexLinear {
                        joint_angles: joint_angles.clone(),
                        sparse,
                        features: m.features,
                        components: m.projection.as_ref().map_or(0, |_| m.parameters),
                        basis: m.basis.as_ref().map_or(0, |b| b.rank),
                    },
                    sections,
                )
            }
            Self::VertexClustered(handles, m) => {
                let (sparse, mut sections) = coefficient_sections(&m.form);
                sections.push(section(
                    *b"CENT",
                    Data::F32(m.clusters.iter().flat_map(|c| c.center.clone()).collect()),
                ));
                sections.push(section(
                    *b"AXES",
                    Data::F32(m.clusters.iter().flat_map(|c| c.axes.clone()).collect()),
                ));
                if let Some(b) = &m.base {
                    sections.extend(linear_weight_sections(&b.weights, BASE_TAGS));
                }
                sections.extend(m.basis.as_ref().map(basis_section));
                // With a basis the clusters' blocks are gone into it: each
                // counts as unmapped.
                let columns = match &m.form {
                    Coefficients::Dense(f) if m.basis.is_none() => {
                        f.blocks[1..].iter().map(|b| b.columns).collect()
                    }
                    _ => vec![m.form.vertices(); m.clusters.len()],
                };
                (
                    Layout::VertexClustered {
                        handles: handles.clone(),
                        dimensions: m.dimensions,
                        alpha: m.alpha,
                        centering: m.centering,
                        clamp: m.clamp,
                        columns,
                        base: m.base.as_ref().map(|b| BaseLayout {
                            joint_angles: b.joint_angles.clone(),
                            features: b.weights.features,
                            components: b
                                .weights
                                .projection
                                .as_ref()
                                .map_or(0, |_| b.weights.parameters),
                        }),
                        basis: m.basis.as_ref().map_or(0, |b| b.rank),
                        sparse,
                    },
                    sections,
                )
            }
        };
        let header = AssetHeader {
            generator: header.generator,
            method,
            algorithm_version: match method.family() {
                crate::Family::Texel => super::super::texel::ALGORITHM_VERSION,
                _ => ALGORITHM_VERSION,
            },
            bake_key: header.bake_key,
            character: header.character,
            clips: header.clips,
            vertices: self.vertices(),
            units: units.to_owned(),
            params: header.params,
            layout,
            rig: Some(skeleton.clone()),
            primitives: header.primitives,
        };
        Container::new(method, &header, sections)
    }

    /// Reads a model back from its container, checking every length
    /// against the header.
    pub fn from_container(container: &Container) -> Result<(Self, AssetHeader), AssetError> {
        Self::from_container_of(container, crate::Family::Vertex)
    }

    /// [`Model::from_container`] of an asset of `family`'s (a texel
    /// method's model is a vertex method's over texels).
    pub(crate) fn from_container_of(
        container: &Container,
        family: crate::Family,
    ) -> Result<(Self, AssetHeader), AssetError> {
        if container.method.family() != family {
            return Err(AssetError::Unsupported(format!(
                "a {} asset is not a {} method's",
                container.method.name(),
                match family {
                    crate::Family::Texel => "texel",
                    _ => "vertex",
                }
            )));
        }
        let header: AssetHeader = container.header()?;
        if header.method != container.method {
            return Err(bad("the header's method differs from the preamble's"));
        }
        validate_layout(&header)?;
        check_primitives(&header.primitives, header.vertices)?;
        if let Some(rig) = &header.rig {
            validate_rig(rig, &header.layout)?;
        }
        let v = header.vertices;
        let coef = f16s(container.section(b"COEF")?)?;
        if coef.iter().any(|c| !c.is_finite()) {
            return Err(bad("COEF holds a value that is not a finite number"));
        }
        let model = match &header.layout {
            Layout::StaticAverage => Self::StaticAverage(StaticAverage {
                form: read_form(v, 1, coef)?,
            }),
            Layout::VertexLinear {
                joint_angles,
                sparse,
                features,
                components,
                basis,
            } => {
                let weights = read_linear_weights(
                    container,
                    joint_angles,
                    *features,
                    *components,
                    LINEAR_TAGS,
                )?;
                let parameters = weights.parameters;
                let rows = parameters + 1;
                let mix = match basis {
                    0 if container.section(b"BMIX").is_ok() => {
                        return Err(bad("a BMIX section without a basis"));
                    }
                    0 => None,
                    &r => Some(read_basis(container, rows, r)?),
                };
                let rows = mix.as_ref().map_or(rows, |b| b.rank + 1);
                let coefficients = if *sparse {
                    Coefficients::Sparse(read_sparse(container, v, rows, coef)?)
                } else {
                    Coefficients::Dense(read_form(v, rows, coef)?)
                };
                Self::VertexLinear(
                    joint_angles.clone(),
                    VertexLinear {
                        coefficients,
                        basis: mix,
                        ..weights
                    },
                )
            }
            Layout::VertexClustered {
                handles,
                dimensions,
                alpha,
                centering,
                clamp,
                columns,
                base,
                basis,
                sparse,
            } => {
                let (m, n, h) = (columns.len(), *dimensions, handles.len());
                let rows = n + usize::from(*centering == Centering::Cluster);
                let base = match base {
                    Some(b) => Some(Box::new(LinearBase {
                        joint_angles: b.joint_angles.clone(),
                        weights: read_linear_weights(
                            container,
                            &b.joint_angles,
                            b.features,
                            b.components,
                            BASE_TAGS,
                        )?,
                    })),
                    None => None,
                };
                let base_rows = base.as_ref().map_or(1, |b| b.weights.parameters + 1);
                let (form, basis) = match basis {
                    0 if *sparse => {
                        return Err(bad("a sparse vertex-clustered model has no basis"));
                    }
                    0 if container.section(b"BMIX").is_ok() => {
                        return Err(bad("a BMIX section without a basis"));
                    }
                    0 => (
                        Coefficients::Dense(read_clustered_form(
                            container, v, base_rows, rows, columns, coef,
                        )?),
                        None,
                    ),
                    &r => {
                        let form = if *sparse {
                            Coefficients::Sparse(read_sparse(container, v, r + 1, coef)?)
                        } else {
                            Coefficients::Dense(read_form(v, r + 1, coef)?)
                        };
                        if columns.iter().any(|&c| c != v) {
                            return Err(bad("a model with a basis has no vertex clusters"));
                        }
                        // Bounded by validate_layout.
                        (form, Some(read_basis(container, base_rows + m * rows, r)?))
                    }
                };
                let Data::F32(centers) = container.section(b"CENT")? else {
                    return Err(bad("CENT must be f32"));
                };
                let Data::F32(axes) = container.section(b"AXES")? else {
                    return Err(bad("AXES must be f32"));
                };
                // validate_layout bounded m, n and h, so these products fit.
                if centers.len() != m * h
                    || axes.len() != m * n * h
                    || centers.iter().chain(axes).any(|x| !x.is_finite())
                {
                    return Err(bad(
                        "cluster centres or axes do not match the header or are not finite",
                    ));
                }
                let clusters = (0..m)
                    .map(|j| PoseCluster {
                        center: centers[j * h..(j + 1) * h].to_vec(),
                        axes: axes[j * n * h..(j + 1) * n * h].to_vec(),
                    })
                    .collect();
                Self::VertexClustered(
                    handles.clone(),
                    VertexClustered {
                        handles: h,
                        dimensions: n,
                        alpha: *alpha,
                        centering: *centering,
                        clamp: *clamp,
                        clusters,
                        form,
                        base,
                        basis,
                    },
                )
            }
        };
        Ok((model, header))
    }
}

/// The sections of stored coefficients, and whether they are sparse
/// (`COEF` values, `CSRO` offsets, `CSRR` rows).
fn coefficient_sections(c: &Coefficients) -> (bool, Vec<Section>) {
    match c {
        Coefficients::Dense(f) => (false, form_sections(f)),
        Coefficients::Sparse(s) => (
            true,
            vec![
                section(*b"COEF", Data::F16(s.values.clone())),
                section(*b"CSRO", Data::U32(s.offsets.clone())),
                section(*b"CSRR", Data::U16(s.rows_of.clone())),
            ],
        ),
    }
}

/// Reads sparse coefficients of `rows` rows (`coef` their values),
/// checking the offsets and rows against them.
fn read_sparse(
    container: &Container,
    v: usize,
    rows: usize,
    coef: Vec<f16>,
) -> Result<SparseForm, AssetError> {
    let Data::U32(offsets) = container.section(b"CSRO")? else {
        return Err(bad("CSRO must be u32"));
    };
    let Data::U16(rows_of) = container.section(b"CSRR")? else {
        return Err(bad("CSRR must be u16"));
    };
    let nnz = coef.len();
    let monotone = offsets.windows(2).all(|w| w[0] <= w[1]);
    if offsets.len() != v + 1
        || offsets.first() != Some(&0)
        || offsets.last().map(|&o| o as usize) != Some(nnz)
        || !monotone
        || rows_of.len() != nnz
        || rows_of.iter().any(|&r| usize::from(r) >= rows)
    {
        return Err(bad("sparse coefficients do not match the header"));
    }
    Ok(SparseForm {
        vertices: v,
        rows,
        offsets: offsets.clone(),
        rows_of: rows_of.clone(),
        values: coef,
    })
}

/// The section tags of a vertex-linear model's weights: means and scales,
/// principal directions.
const LINEAR_TAGS: [[u8; 4]; 2] = [*b"NORM", *b"PROJ"];
/// The same for vertex-clustered's linear base.
const BASE_TAGS: [[u8; 4]; 2] = [*b"BNRM", *b"BPRJ"];

/// Reads what turns joint angles into a vertex-linear model's weights
/// (`tags`: the means-and-scales and projection sections), checked against
/// the header; the coefficients are left empty.
fn read_linear_weights(
    container: &Container,
    joint_angles: &JointAngles,
    features: Features,
    components: usize,
    tags: [[u8; 4]; 2],
) -> Result<VertexLinear, AssetError> {
    let rotations = joint_angles.joints.len();
    let n = features.count(joint_angles.len(), rotations);
    if components > n {
        return Err(bad("more principal directions than features"));
    }
    let name = |t: [u8; 4]| String::from_utf8_lossy(&t).into_owned();
    let projection = if components > 0 {
        let Data::F32(d) = container.section(&tags[1])? else {
            return Err(bad(&format!("{} must be f32", name(tags[1]))));
        };
        if d.len() != components * n || d.iter().any(|x| !x.is_finite()) {
            return Err(bad(&format!(
                "{} does not match the header or is not finite",
                name(tags[1])
            )));
        }
        Some(d.clone())
    } else {
        None
    };
    let Data::F32(norm) = container.section(&tags[0])? else {
        return Err(bad(&format!("{} must be f32", name(tags[0]))));
    };
    if norm.len() != 2 * n || norm.iter().any(|x| !x.is_finite()) {
        return Err(bad(&format!(
            "{} does not match the header or is not finite",
            name(tags[0])
        )));
    }
    Ok(VertexLinear {
        parameters: if components > 0 { components } else { n },
        features,
        rotations,
        projection,
        mean: norm[..n].to_vec(),
        inv_std: norm[n..].to_vec(),
        ranges: joint_angles.ranges.clone(),
        coefficients: Coefficients::Dense(LinearForm {
            vertices: 0,
            blocks: Vec::new(),
        }),
        basis: None,
    })
}

/// `BMIX`: a basis's mix, then its offsets.
fn basis_section(b: &Basis) -> Section {
    section(
        *b"BMIX",
        Data::F32(b.mix.iter().chain(&b.offset).copied().collect()),
    )
}

/// Reads a basis of `rank` rows over `inputs` weights from `BMIX`.
fn read_basis(container: &Container, inputs: usize, rank: usize) -> Result<Basis, AssetError> {
    let Data::F32(d) = container.section(b"BMIX")? else {
        return Err(bad("BMIX must be f32"));
    };
    // rank ≤ MAX_BASIS and inputs are bounded by validate_layout.
    if d.len() != (inputs + 1) * rank || d.iter().any(|x| !x.is_finite()) {
        return Err(bad("BMIX does not match the header or is not finite"));
    }
    Ok(Basis {
        inputs,
        rank,
        mix: d[..inputs * rank].to_vec(),
        offset: d[inputs * rank..].to_vec(),
    })
}

/// The sections of a vertex-linear model's weights.
fn linear_weight_sections(m: &VertexLinear, tags: [[u8; 4]; 2]) -> Vec<Section> {
    let mut sections = vec![section(
        tags[0],
        Data::F32(m.mean.iter().chain(&m.inv_std).copied().collect()),
    )];
    if let Some(d) = &m.projection {
        sections.push(section(tags[1], Data::F32(d.clone())));
    }
    sections
}

/// Most vertices, joints, pose clusters and dimensions an asset may
/// declare: far above any real bake, low enough that every size computed
/// from them fits in memory arithmetic without overflow.
const MAX_VERTICES: usize = 1 << 26;
const MAX_JOINTS: usize = 1 << 12;
const MAX_POSE_CLUSTERS: usize = 1024;
const MAX_DIMENSIONS: usize = 256;
const MAX_BASIS: usize = 4096;
const MAX_NODES: usize = 1 << 16;

/// Checks a joint-angle layout's lengths and ranges.
fn validate_joint_angles(ja: &JointAngles) -> Result<(), AssetError> {
    let count = ja.joints.len() + ja.translations.len() + ja.scales.len();
    if count > MAX_JOINTS || ja.names.len() != 3 * count || ja.ranges.len() != 3 * count {
        return Err(bad(
            "the joint-angle layout's names and ranges do not match its joints",
        ));
    }
    if ja
        .ranges
        .iter()
        .any(|r| !(r.min.is_finite() && r.max.is_finite() && r.min <= r.max))
    {
        return Err(bad("a joint-angle range is not finite or is reversed"));
    }
    Ok(())
}

/// Checks that the header's layout is self-consistent and within bounds
/// before any section is interpreted with it, so that a file that passes
/// its checksums but was written by someone hostile is refused with a
/// message instead of making evaluation panic or produce NaN.
fn validate_layout(header: &AssetHeader) -> Result<(), AssetError> {
    let v = header.vertices;
    if v == 0 || v > MAX_VERTICES {
        return Err(bad("the vertex count is 0 or absurdly large"));
    }
    match &header.layout {
        Layout::StaticAverage => {}
        Layout::VertexLinear {
            joint_angles,
            basis,
            ..
        } => {
            validate_joint_angles(joint_angles)?;
            if *basis > MAX_BASIS {
                return Err(bad("the basis has more than 4096 rows"));
            }
        }
        Layout::VertexClustered {
            handles,
            dimensions,
            alpha,
            clamp,
            columns,
            base,
            basis,
            ..
        } => {
            if *basis > MAX_BASIS {
                return Err(bad("the basis has more than 4096 rows"));
            }
            if let Some(b) = base {
                validate_joint_angles(&b.joint_angles)?;
            }
            if handles.joints.is_empty()
                || handles.joints.len() > MAX_JOINTS
                || handles.offsets.len() != handles.joints.len()
                || handles.offsets.iter().any(|o| !o.is_finite())
            {
                return Err(bad(
                    "the handle layout is empty or its offsets do not match its joints",
                ));
            }
            if *dimensions == 0 || *dimensions > MAX_DIMENSIONS {
                return Err(bad("dimensions must be between 1 and 256"));
            }
            if columns.is_empty() || columns.len() > MAX_POSE_CLUSTERS {
                return Err(bad("pose clusters must be between 1 and 1024"));
            }
            let alpha_ok = alpha.is_finite() && *alpha > 0.0;
            let clamp_ok = clamp.is_finite() && *clamp >= 0.0;
            if !(alpha_ok && clamp_ok) {
                return Err(bad(
                    "alpha must be finite and positive, clamp finite and ≥ 0",
                ));
            }
        }
    }
    Ok(())
}

/// Checks the rig's hierarchy, and that every node the layout reads is one
/// of its nodes.
fn validate_rig(rig: &Skeleton, layout: &Layout) -> Result<(), AssetError> {
    if rig.nodes.len() > MAX_NODES {
        return Err(bad("the rig has more than 65536 nodes"));
    }
    rig.check().map_err(|e| bad(&e))?;
    if rig.nodes.iter().any(|n| {
        !(n.rest.translation.is_finite() && n.rest.rotation.is_finite() && n.rest.scale.is_finite())
    }) {
        return Err(bad("a rest transform of the rig is not finite"));
    }
    let fits = match layout {
        Layout::StaticAverage => Ok(()),
        Layout::VertexLinear { joint_angles, .. } => joint_angles.check(rig),
        Layout::VertexClustered { handles, base, .. } => handles
            .check(rig)
            .and_then(|()| base.as_ref().map_or(Ok(()), |b| b.joint_angles.check(rig))),
    };
    fits.map_err(|e| bad(&format!("the layout does not fit the rig: {e}")))
}

fn section(tag: [u8; 4], data: Data) -> Section {
    Section { tag, data }
}

fn bad(what: &str) -> AssetError {
    AssetError::Malformed(what.to_owned())
}

fn f16s(data: &Data) -> Result<Vec<f16>, AssetError> {
    match data {
        Data::F16(v) => Ok(v.clone()),
        _ => Err(bad("COEF must be f16")),
    }
}

/// `COEF` (every block's coefficients, concatenated) and, when any block
/// has a vertex-cluster map, `VMAP` (the maps, concatenated; u16 when
/// every block has at most 65536 columns).
fn form_sections(form: &LinearForm) -> Vec<Section> {
    let mut sections = vec![section(
        *b"COEF",
        Data::F16(
            form.blocks
                .iter()
                .flat_map(|b| b.coefficients.iter().copied())
                .collect(),
        ),
    )];
    let maps: Vec<&Block> = form.blocks.iter().filter(|b| b.map.is_some()).collect();
    if !maps.is_empty() {
        let all = maps.iter().flat_map(|b| b.map.iter().flatten().copied());
        let narrow = maps.iter().all(|b| form::map_entry_bytes(b.columns) == 2);
        sections.push(section(
            *b"VMAP",
            if narrow {
                Data::U16(all.map(|c| c as u16).collect())
            } else {
                Data::U32(all.collect())
            },
        ));
    }
    sections
}

/// One unmapped block of `rows` rows and V columns.
fn read_form(v: usize, rows: usize, coef: Vec<f16>) -> Result<LinearForm, AssetError> {
    if Some(coef.len()) != rows.checked_mul(v) {
        return Err(bad("COEF length does not match the header"));
    }
    Ok(LinearForm {
        vertices: v,
        blocks: vec![Block {
            rows,
            columns: v,
            coefficients: coef,
            map: None,
        }],
    })
}

/// The mean block, then one block of `rows` rows per pose cluster with the
/// given column counts; blocks with fewer columns than vertices read their
/// map from `VMAP`.
fn read_clustered_form(
    container: &Container,
    v: usize,
    base_rows: usize,
    rows: usize,
    columns: &[usize],
    coef: Vec<f16>,
) -> Result<LinearForm, AssetError> {
    if columns.iter().any(|&c| c == 0 || c > v) {
        return Err(bad(
            "vertex cluster counts must be between 1 and the vertex count",
        ));
    }
    // Bounded by validate_layout: v ≤ 2^26, rows ≤ 257, ≤ 1024 clusters.
    let want = v * base_rows + columns.iter().map(|c| c * rows).sum::<usize>();
    if coef.len() != want {
        return Err(bad("COEF length does not match the header"));
    }
    let mapped = columns.iter().filter(|&&c| c < v).count();
    let maps: Vec<u32> = if mapped > 0 {
        match container.section(b"VMAP")? {
            Data::U16(m) => m.iter().map(|&x| u32::from(x)).collect(),
            Data::U32(m) => m.clone(),
            _ => return Err(bad("VMAP must be u16 or u32")),
        }
    } else {
        Vec::new()
    };
    if maps.len() != mapped * v {
        return Err(bad("VMAP length does not match the header"));
    }
    let mut blocks = vec![Block {
        rows: base_rows,
        columns: v,
        coefficients: coef[..v * base_rows].to_vec(),
        map: None,
    }];
    let (mut at, mut map_at) = (v * base_rows, 0);
    for &c in columns {
        let map = if c < v {
            let m = maps[map_at..map_at + v].to_vec();
            map_at += v;
            if m.iter().any(|&x| x as usize >= c) {
                return Err(bad("VMAP names a vertex cluster that does not exist"));
            }
            Some(m)
        } else {
            None
        };
        blocks.push(Block {
            rows,
            columns: c,
            coefficients: coef[at..at + rows * c].to_vec(),
            map,
        });
        at += rows * c;
    }
    Ok(LinearForm {
        vertices: v,
        blocks,
    })
}
