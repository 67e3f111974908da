//! A baked grid set in the asset container (DESIGN §7). The JSON header
//! lists the parts (name, palette entry, node, grid box, V_M) and whether
//! the cones are baked; the sections hold the cells exactly as an engine
//! uploads them, part after part, each `n³` cells x fastest:
//!
//! * `OCCL` (without cones): one byte a cell, ao_grid = 2·b/255;
//! * `RGBA` (with cones): four bytes a cell, the axis in RGB
//!   (d = 2·b/255 − 1, the part's bind space) and the occlusion in A, one
//!   RGBA8-unorm texel as the paper stores it;
//! * `TCLP` (with cones): the `T_clip` table, (occlusion, f) as f32 pairs,
//!   aperture-major;
//! * `VOFS` and `GOFS` (with a static base, format 1.5): the base's
//!   offsets, f16, per vertex of the character and per texel of the
//!   ground square (x fastest); the header's `base` holds the gains and
//!   the square. A 1.4 reader ignores them and plays the grids alone.
//!
//! Reading checks every number and every section's length, so a hostile
//! file with valid checksums is refused with a message.

use crate::method::Method;
use serde::{Deserialize, Serialize};

use super::{
    ALGORITHM_VERSION, GridBox, MAX_PARTS,
    base::{GroundBase, GroundSquare, StaticBase},
    model::{GridModel, PartGrid},
    tclip::TClip,
};
use crate::container::{
    AssetError, AssetHeaderFields, Container, Data, PrimitiveSpan, Section, check_primitives,
};
use crate::method::ground::{halves, read_halves};

/// What the stored values mean, written into every header.
pub const UNITS: &str = "occlusion each part casts into space: ao_grid = 2 x the occluded fraction of the sphere, rescaled to 0 on the grid's boundary";

/// One part as the header lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartLayout {
    /// The part's name (its node's).
    pub name: String,
    /// Its palette entry.
    pub joint: usize,
    /// Its node.
    pub node: usize,
    /// Where its grid sits in bind space.
    pub grid: GridBox,
    /// V_M.
    pub boundary_max: f32,
    /// Cells filled from their neighbours.
    pub inside: usize,
}

/// A grid asset's JSON header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridHeader {
    /// The program that wrote it.
    pub generator: String,
    /// The method.
    pub method: Method,
    /// [`ALGORITHM_VERSION`] of the writer.
    pub algorithm_version: u32,
    /// The bake key.
    pub bake_key: String,
    /// sha256 of the character upload.
    pub character: String,
    /// sha256 of each clip upload.
    pub clips: Vec<String>,
    /// What the values mean.
    pub units: String,
    /// The bake's fully defaulted parameters.
    pub params: serde_json::Value,
    /// The parts, in the order of their cells.
    pub parts: Vec<PartLayout>,
    /// Whether the cones (RGBA cells and `T_clip`) are baked.
    pub cones: bool,
    /// `T_clip`'s samples per axis (0 without cones).
    pub tclip_resolution: usize,
    /// The static base's layout, when the asset has one (format 1.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base: Option<BaseLayout>,
    /// Where each glTF primitive's vertices are, in the order a grid
    /// bake's receivers and `VOFS` take them (format 1.6; empty before).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub primitives: Vec<PrimitiveSpan>,
}

/// The static base as the header describes it; its offsets are the
/// `VOFS` and `GOFS` sections.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BaseLayout {
    /// Vertices of the character (`VOFS`'s length).
    pub vertices: usize,
    /// Per part, the gain at its vertices.
    pub part_gains: Vec<f32>,
    /// The gain on the ground.
    pub ground_gain: f32,
    /// The ground texture's square (`GOFS` holds its texels).
    pub ground: GroundSquare,
}

/// Most vertices a base may hold offsets for.
pub const MAX_VERTICES: usize = 1 << 24;

impl GridModel {
    /// The asset: header and sections.
    pub fn to_container(&self, fields: AssetHeaderFields) -> Container {
        let parts = self
            .parts
            .iter()
            .map(|p| PartLayout {
                name: p.name.clone(),
                joint: p.joint,
                node: p.node,
                grid: p.grid,
                boundary_max: p.boundary_max,
                inside: p.inside,
            })
            .collect();
        let header = GridHeader {
            generator: fields.generator,
            method: Method::Grid,
            algorithm_version: ALGORITHM_VERSION,
            bake_key: fields.bake_key,
            character: fields.character,
            clips: fields.clips,
            units: UNITS.to_owned(),
            params: fields.params,
            parts,
            cones: self.cones(),
            tclip_resolution: self.tclip.as_ref().map_or(0, |t| t.resolution),
            base: self.base.as_ref().map(|b| BaseLayout {
                vertices: b.vertex_offsets.len(),
                part_gains: b.part_gains.clone(),
                ground_gain: b.ground.gain,
                ground: b.ground.square,
            }),
            primitives: fields.primitives,
        };
        let mut sections = Vec::new();
        match &self.tclip {
            Some(t) => {
                let mut rgba = Vec::new();
                for p in &self.parts {
                    let dirs = p.directions.as_deref().unwrap_or_default();
                    for (i, &a) in p.occlusion.iter().enumerate() {
                        let d = dirs.get(i).copied().unwrap_or([128; 3]);
                        rgba.extend([d[0], d[1], d[2], a]);
                    }
                }
                sections.push(Section {
                    tag: *b"RGBA",
                    data: Data::U8(rgba),
                });
                sections.push(Section {
                    tag: *b"TCLP",
                    data: Data::F32(t.values.iter().flatten().copied().collect()),
                });
            }
            None => sections.push(Section {
                tag: *b"OCCL",
                data: Data::U8(
                    self.parts
                        .iter()
                        .flat_map(|p| p.occlusion.clone())
                        .collect(),
                ),
            }),
        }
        if let Some(b) = &self.base {
            sections.push(Section {
                tag: *b"VOFS",
                data: halves(&b.vertex_offsets),
            });
            sections.push(Section {
                tag: *b"GOFS",
                data: b.ground.section_data(),
            });
        }
        Container::new(Method::Grid, &header, sections)
    }

    /// Reads a model back, checking the layout and the sections' lengths.
    pub fn from_container(container: &Container) -> Result<(Self, GridHeader), AssetError> {
        // Another family's asset is named before its header is read as a
        // grid's (which would only say a field is missing).
        if container.method != Method::Grid {
            return Err(AssetError::Unsupported(format!(
                "a {} asset is not a grid",
                container.method.name()
            )));
        }
        let header: GridHeader = container.header()?;
        // The vertices the spans tile: the base's (whose count the base's
        // reader checks), or theirs (nothing is sized by them).
        let vertices = header.base.as_ref().map_or_else(
            || {
                header
                    .primitives
                    .last()
                    .map_or(0, |s| s.first.saturating_add(s.count))
            },
            |b| b.vertices,
        );
        check_primitives(&header.primitives, vertices)?;
        if header.method != Method::Grid || container.method != Method::Grid {
            return Err(bad("the asset is not a grid"));
        }
        if header.parts.is_empty() || header.parts.len() > MAX_PARTS {
            return Err(bad(&format!(
                "the part count must be between 1 and {MAX_PARTS}"
            )));
        }
        let mut cells = 0usize;
        for p in &header.parts {
            let g = &p.grid;
            if !(2..=128).contains(&g.resolution) {
                return Err(bad(&format!(
                    "part {:?}: the resolution must be between 2 and 128",
                    p.name
                )));
            }
            if !(g.centre.is_finite() && g.half.is_finite() && g.half.min_element() > 0.0) {
                return Err(bad(&format!(
                    "part {:?}: the grid box is not finite and positive",
                    p.name
                )));
            }
            if !p.boundary_max.is_finite() {
                return Err(bad(&format!("part {:?}: V_M is not finite", p.name)));
            }
            cells += g.cells();
        }
        let per_cell = if header.cones { 4 } else { 1 };
        let tag = if header.cones { b"RGBA" } else { b"OCCL" };
        let Data::U8(bytes) = container.section(tag)? else {
            return Err(bad("the cells must be bytes"));
        };
        if bytes.len() != cells * per_cell {
            return Err(bad(&format!(
                "the cells hold {} bytes where the parts need {}",
                bytes.len(),
                cells * per_cell
            )));
        }
        let tclip = if header.cones {
            let r = header.tclip_resolution;
            if !(2..=256).contains(&r) {
                return Err(bad("the T_clip resolution must be between 2 and 256"));
            }
            let Data::F32(v) = container.section(b"TCLP")? else {
                return Err(bad("TCLP must be f32"));
            };
            if v.len() != 2 * r * r || v.iter().any(|x| !(0.0..=1.0).contains(x)) {
                return Err(bad(&format!(
                    "TCLP must hold {} numbers in [0, 1]",
                    2 * r * r
                )));
            }
            Some(TClip {
                resolution: r,
                values: v.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
            })
        } else {
            None
        };
        let mut offset = 0;
        let parts = header
            .parts
            .iter()
            .map(|p| {
                let n = p.grid.cells();
                let cells = &bytes[offset * per_cell..(offset + n) * per_cell];
                offset += n;
                let (occlusion, directions) = if header.cones {
                    (
                        cells.chunks_exact(4).map(|c| c[3]).collect(),
                        Some(cells.chunks_exact(4).map(|c| [c[0], c[1], c[2]]).collect()),
                    )
                } else {
                    (cells.to_vec(), None)
                };
                PartGrid {
                    name: p.name.clone(),
                    joint: p.joint,
                    node: p.node,
                    grid: p.grid,
                    boundary_max: p.boundary_max,
                    inside: p.inside,
                    occlusion,
                    directions,
                }
            })
            .collect();
        let base = match &header.base {
            Some(layout) => Some(read_base(container, layout, header.parts.len())?),
            None => None,
        };
        Ok((Self { parts, tclip, base }, header))
    }

    /// Checks the model against a character's palette: every part's
    /// palette entry must exist.
    pub fn check_palette(&self, joints: usize) -> Result<(), AssetError> {
        match self.parts.iter().find(|p| p.joint >= joints) {
            Some(p) => Err(AssetError::Mismatch(format!(
                "part {:?} follows palette entry {}, but the palette has {joints} entries",
                p.name, p.joint
            ))),
            None => Ok(()),
        }
    }
}

/// The static base from its layout and sections, every number checked.
fn read_base(
    container: &Container,
    layout: &BaseLayout,
    parts: usize,
) -> Result<StaticBase, AssetError> {
    if layout.vertices > MAX_VERTICES {
        return Err(bad(&format!(
            "the base's vertex count must be at most {MAX_VERTICES}"
        )));
    }
    if layout.part_gains.len() != parts {
        return Err(bad("the base must hold one gain per part"));
    }
    if !layout.part_gains.iter().all(|k| k.is_finite()) {
        return Err(bad("the base's gains must be finite"));
    }
    Ok(StaticBase {
        vertex_offsets: read_halves(container, b"VOFS", layout.vertices)?,
        part_gains: layout.part_gains.clone(),
        ground: GroundBase::read(container, layout.ground, layout.ground_gain, b"GOFS")?,
    })
}

fn bad(what: &str) -> AssetError {
    AssetError::Malformed(what.to_owned())
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    fn model(cones: bool) -> GridModel {
        let part = |k: usize, n: usize| PartGrid {
            name: format!("part {k}"),
            joint: k,
            node: k + 1,
            grid: GridBox {
                centre: Vec3::new(k as f32, 0.0, 0.0),
                half: Vec3::new(1.0, 2.0, 0.5),
                resolution: n,
            },
            boundary_max: 0.05,
            inside: 3,
            occlusion: (0..n * n * n).map(|i| (i * 7) as u8).collect(),
            directions: cones.then(|| (0..n * n * n).map(|i| [i as u8, 1, 2]).collect()),
        };
        GridModel {
            parts: vec![part(0, 3), part(1, 2)],
            tclip: cones.then(|| TClip::compute(4)),
            base: None,
        }
    }

    #[test]
    fn a_model_round_trips_through_its_container_bit_for_bit() {
        for cones in [false, true] {
            let m = model(cones);
            let bytes = m.to_container(AssetHeaderFields::for_tests()).to_bytes();
            let (back, header) =
                GridModel::from_container(&Container::from_bytes(&bytes).unwrap()).unwrap();
            assert_eq!(back, m);
            assert_eq!(header.parts.len(), 2);
            assert_eq!(header.cones, cones);
            assert_eq!(m.bytes(), if cones { 4 * 35 + 8 * 16 } else { 35 });
        }
    }

    fn base() -> StaticBase {
        StaticBase {
            vertex_offsets: vec![0.25, -0.5, 0.125],
            part_gains: vec![0.75, 1.5],
            ground: GroundBase {
                square: GroundSquare {
                    min: [-2.0, -3.0],
                    size: 4.0,
                    height: 0.5,
                    resolution: 2,
                },
                gain: 0.5,
                offsets: vec![0.0, 0.0625, -0.25, 1.0],
            },
        }
    }

    #[test]
    fn a_base_round_trips_and_a_hostile_one_is_refused_by_name() {
        let mut m = model(true);
        m.base = Some(base());
        let bytes = m.to_container(AssetHeaderFields::for_tests()).to_bytes();
        let (back, header) =
            GridModel::from_container(&Container::from_bytes(&bytes).unwrap()).unwrap();
        assert_eq!(back, m);
        assert_eq!(header.base.unwrap().vertices, 3);
        assert_eq!(m.bytes(), 4 * 35 + 8 * 16 + 2 * 7 + 4 * 2);
        type Break = fn(&mut StaticBase);
        let cases: [(&str, Break); 3] = [
            ("one gain per part", |b| {
                b.part_gains.pop();
            }),
            ("ground square", |b| b.ground.square.size = 0.0),
            ("GOFS must hold 4", |b| {
                b.ground.offsets.pop();
            }),
        ];
        for (what, break_it) in cases {
            let mut m = model(false);
            let mut b = base();
            break_it(&mut b);
            m.base = Some(b);
            let c =
                Container::from_bytes(&m.to_container(AssetHeaderFields::for_tests()).to_bytes())
                    .unwrap();
            let e = GridModel::from_container(&c).unwrap_err().to_string();
            assert!(e.contains(what), "{what}: {e}");
        }
    }

    #[test]
    fn a_hostile_layout_is_refused_by_name() {
        type Break = fn(&mut GridModel);
        let cases: [(&str, Break); 3] = [
            ("resolution", |m| m.parts[0].grid.resolution = 1000),
            ("grid box", |m| m.parts[1].grid.half.y = -1.0),
            ("cells hold", |m| {
                m.parts[1].occlusion.pop();
            }),
        ];
        for (what, break_it) in cases {
            let mut m = model(false);
            break_it(&mut m);
            let c =
                Container::from_bytes(&m.to_container(AssetHeaderFields::for_tests()).to_bytes())
                    .unwrap();
            let e = GridModel::from_container(&c).unwrap_err().to_string();
            assert!(e.contains(what), "{what}: {e}");
        }
        // T_clip's occlusions and blends are fractions; 1e30 would turn a
        // lookup into inf − inf.
        let mut m = model(true);
        m.tclip.as_mut().unwrap().values[3][1] = 1e30;
        let c = Container::from_bytes(&m.to_container(AssetHeaderFields::for_tests()).to_bytes())
            .unwrap();
        let e = GridModel::from_container(&c).unwrap_err().to_string();
        assert!(e.contains("TCLP must hold") && e.contains("[0, 1]"), "{e}");
        let m = model(false);
        assert!(m.check_palette(2).is_ok());
        let e = m.check_palette(1).unwrap_err();
        assert!(
            matches!(e, AssetError::Mismatch(_)),
            "the caller's palette, not the file: {e}"
        );
        assert!(e.to_string().contains("the palette has 1 entries"), "{e}");
    }
}
