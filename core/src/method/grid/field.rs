//! A part's grid: where it is (Eq. 4), what its cells hold (Eq. 5, one
//! z-layer at a time, as `slab` jobs compute it), and the finishing steps
//! of §3.3 that turn the traced cells into what the asset stores.

use glam::Vec3;

pub use aobake_runtime::method::grid::GridBox;

use crate::trace::{
    Scene, SceneOptions, TraceError, VolumeParams, no_progress, volume_occlusion_many,
};

/// The grid around `positions` (a part in bind space) by Eq. 4:
/// e_i = r_i + √(A_i / 4πε), r_i the bounding box's half size and A_i
/// its area seen along axis i. A flat or thin part keeps a grid of at
/// least a thousandth of its largest size along every axis.
pub fn around(positions: &[Vec3], epsilon: f32, resolution: usize) -> GridBox {
    let (lo, hi) =
        crate::geometry::bounds(positions.iter().copied()).unwrap_or((Vec3::ZERO, Vec3::ZERO));
    let r = (hi - lo) * 0.5;
    let floor = (r.max_element() * 1e-3).max(1e-6);
    let area = Vec3::new(4.0 * r.y * r.z, 4.0 * r.x * r.z, 4.0 * r.x * r.y);
    let half = r + (area / (4.0 * std::f32::consts::PI * epsilon)).map(f32::sqrt);
    GridBox {
        centre: (lo + hi) * 0.5,
        half: half.max(Vec3::splat(floor)),
        resolution,
    }
}

/// How far Eq. 4 reaches beyond the part's bounding box along its
/// longest-reaching axis: max_i √(A_i / 4πε). Beyond it the part's
/// occlusion is below ε.
pub fn reach(positions: &[Vec3], epsilon: f32) -> f32 {
    let (lo, hi) =
        crate::geometry::bounds(positions.iter().copied()).unwrap_or((Vec3::ZERO, Vec3::ZERO));
    let r = (hi - lo) * 0.5;
    let area = Vec3::new(4.0 * r.y * r.z, 4.0 * r.x * r.z, 4.0 * r.x * r.y);
    (area / (4.0 * std::f32::consts::PI * epsilon))
        .map(f32::sqrt)
        .max_element()
}

/// One traced cell.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RawCell {
    /// ao′ of Eq. 5: the occluded fraction of the sphere, 0..1.
    pub occlusion: f32,
    /// The unit average occluded direction (bind space), zero if none.
    pub direction: Vec3,
    /// The sample point is inside the part.
    pub inside: bool,
}

/// The seed of layer `z` of part `part`: a layer's rays depend on the
/// bake's seed and the layer alone, so however the grid is cut into slabs
/// (and however often a slab is interrupted) its cells are the same.
fn layer_seed(seed: u64, part: usize, z: usize) -> u64 {
    let mut h = seed ^ 0x6772_6964_2121_2121; // "grid!!!!"
    for v in [part as u64, z as u64] {
        h = (h ^ v).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        h ^= h >> 29;
    }
    h
}

/// Traces z-layers `layers` of a part's grid: the part alone (its
/// triangles in bind space), `rays` directions uniform on the sphere per
/// cell. `done` is called after each layer with it and its cells, in
/// order; an `Err` from it stops the trace.
pub fn trace_layers<E: From<TraceError>>(
    scene: &Scene,
    grid: &GridBox,
    part: usize,
    layers: std::ops::Range<usize>,
    params: VolumeParams,
    done: &mut dyn FnMut(usize, Vec<RawCell>) -> Result<(), E>,
) -> Result<(), E> {
    let n = grid.resolution;
    // On a GPU tracer, layers are traced in batches of about 64k cells;
    // on the CPU one by one (each checkpointed before the next is traced).
    let per_batch = crate::trace::engine::batch_items(n * n, 65_536, usize::MAX);
    let layers: Vec<usize> = layers.collect();
    for batch in layers.chunks(per_batch) {
        let points: Vec<Vec<Vec3>> = batch
            .iter()
            .map(|&z| {
                (0..n * n)
                    .map(|i| grid.cell_centre(i % n, i / n, z))
                    .collect()
            })
            .collect();
        let groups: Vec<(&[Vec3], u64)> = batch
            .iter()
            .zip(&points)
            .map(|(&z, p)| (p.as_slice(), layer_seed(params.seed, part, z)))
            .collect();
        let traced = volume_occlusion_many(scene, &groups, &params, &no_progress)?;
        for (&z, samples) in batch.iter().zip(traced) {
            let cells = samples
                .into_iter()
                .map(|s| RawCell {
                    occlusion: 0.5 * s.occlusion,
                    direction: s.direction,
                    inside: s.inside,
                })
                .collect();
            done(z, cells)?;
        }
    }
    Ok(())
}

/// The scene a part's cells are traced in: the part alone, bind space.
pub fn part_scene(positions: &[Vec3], triangles: &[[u32; 3]]) -> Result<Scene, TraceError> {
    Scene::new(positions, triangles, &SceneOptions::default())
}

/// A run of traced z-layers of one part, as a blob: `AOSL`, format 1,
/// part, resolution, first layer, layers (u32 each), then per cell
/// occlusion, direction x, y, z and inside (0 or 1) as little-endian f32,
/// x fastest, then y, then z.
#[derive(Debug, Clone, PartialEq)]
pub struct Slab {
    /// The part.
    pub part: usize,
    /// Cells per grid edge.
    pub resolution: usize,
    /// The first layer.
    pub first: usize,
    /// The cells, layer after layer.
    pub cells: Vec<RawCell>,
}

const SLAB_MAGIC: &[u8; 4] = b"AOSL";
const SLAB_HEAD: usize = 24;

impl Slab {
    /// Layers held.
    pub fn layers(&self) -> usize {
        self.cells.len() / (self.resolution * self.resolution).max(1)
    }

    /// The blob.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(SLAB_HEAD + 20 * self.cells.len());
        out.extend(SLAB_MAGIC);
        for v in [1, self.part, self.resolution, self.first, self.layers()] {
            out.extend((v as u32).to_le_bytes());
        }
        for c in &self.cells {
            for v in [
                c.occlusion,
                c.direction.x,
                c.direction.y,
                c.direction.z,
                f32::from(u8::from(c.inside)),
            ] {
                out.extend(v.to_le_bytes());
            }
        }
        out
    }

    /// Reads a blob back; `resolution` is the bake's.
    pub fn from_bytes(bytes: &[u8], resolution: usize) -> Result<Self, String> {
        let bad = |what: &str| format!("a grid slab is malformed: {what}");
        if bytes.len() < SLAB_HEAD || &bytes[..4] != SLAB_MAGIC {
            return Err(bad("no AOSL header"));
        }
        let at = |i: usize| {
            u32::from_le_bytes(bytes[4 + 4 * i..8 + 4 * i].try_into().expect("4 bytes")) as usize
        };
        let (format, part, res, first, layers) = (at(0), at(1), at(2), at(3), at(4));
        if format != 1 {
            return Err(bad("unknown format"));
        }
        if res != resolution {
            return Err(bad("its resolution is not the bake's"));
        }
        if first.checked_add(layers).is_none_or(|end| end > res) {
            return Err(bad("its layers are outside the grid"));
        }
        let cells = layers * res * res;
        let body = &bytes[SLAB_HEAD..];
        if body.len() != cells * 20 {
            return Err(bad("its length does not match its header"));
        }
        let cells = body
            .chunks_exact(20)
            .map(|c| {
                let f = |i: usize| f32::from_le_bytes(c[4 * i..4 * i + 4].try_into().expect("4"));
                RawCell {
                    occlusion: f(0),
                    direction: Vec3::new(f(1), f(2), f(3)),
                    inside: f(4) != 0.0,
                }
            })
            .collect::<Vec<_>>();
        if cells
            .iter()
            .any(|c| !(c.occlusion.is_finite() && c.direction.is_finite()))
        {
            return Err(bad("a cell is not finite"));
        }
        Ok(Self {
            part,
            resolution: res,
            first,
            cells,
        })
    }
}

/// The finished cells of one part, what the asset stores: occlusion as a
/// byte (`b` means ao_grid = 2·b/255, the paper's ×2 storage of the
/// rescaled ao′) and, with cones, the average occluded direction in the
/// part's bind space as three bytes (`d = 2·b/255 − 1`, so an engine can
/// upload the four bytes of a cell as one RGBA8 unorm texel, A the
/// occlusion).
#[derive(Debug, Clone, PartialEq)]
pub struct Finished {
    /// One byte per cell.
    pub occlusion: Vec<u8>,
    /// Three bytes per cell, with cones.
    pub directions: Option<Vec<[u8; 3]>>,
    /// V_M, the largest value on the boundary before the rescale.
    pub boundary_max: f32,
    /// Cells inside the occluder, filled from their neighbours.
    pub inside: usize,
}

/// The finishing steps of §3.3 on a part's traced cells:
///
/// 1. the boundary rescale V′ = (V − V_M)/(1 − V_M), V_M the largest value
///    on the grid's boundary, so that the contact shadow ends at zero on
///    the boundary (§3.3.2);
/// 2. every cell inside the occluder (value 1, or a back face first for
///    most of its rays) replaced by the mean of its outside neighbours
///    among the 26 around it (§3.3.3); cells with none are filled in
///    later passes from cells filled before them (the paper does one pass;
///    a thick part needs more to reach its core, which is never looked up
///    but is interpolated at the surface);
/// 3. quantised: the occlusion ×2 in a byte, the direction in three.
pub fn finish(cells: &[RawCell], resolution: usize, cones: bool) -> Finished {
    let n = resolution;
    let inside: Vec<bool> = cells
        .iter()
        .map(|c| c.inside || c.occlusion >= 1.0 - 1e-6)
        .collect();
    let index = |x: usize, y: usize, z: usize| (z * n + y) * n + x;
    let mut boundary_max = 0.0f32;
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let edge = [x, y, z].iter().any(|&c| c == 0 || c == n - 1);
                let i = index(x, y, z);
                if edge && !inside[i] {
                    boundary_max = boundary_max.max(cells[i].occlusion);
                }
            }
        }
    }
    let vm = boundary_max.min(0.999);
    let mut value: Vec<f32> = cells
        .iter()
        .map(|c| ((c.occlusion - vm) / (1.0 - vm)).max(0.0))
        .collect();
    let mut direction: Vec<Vec3> = cells.iter().map(|c| c.direction).collect();
    let mut known: Vec<bool> = inside.iter().map(|&i| !i).collect();
    let mut missing: Vec<usize> = (0..cells.len()).filter(|&i| !known[i]).collect();
    let filled = missing.len();
    while !missing.is_empty() {
        let mut updates = Vec::new();
        for &i in &missing {
            let (x, y, z) = (i % n, (i / n) % n, i / (n * n));
            let (mut sum, mut dir, mut count) = (0.0f32, Vec3::ZERO, 0u32);
            for dz in -1i64..=1 {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let (a, b, c) = (x as i64 + dx, y as i64 + dy, z as i64 + dz);
                        let range = 0..n as i64;
                        if !(range.contains(&a) && range.contains(&b) && range.contains(&c)) {
                            continue;
                        }
                        let j = index(a as usize, b as usize, c as usize);
                        if known[j] {
                            sum += value[j];
                            dir += direction[j];
                            count += 1;
                        }
                    }
                }
            }
            if count > 0 {
                updates.push((i, sum / count as f32, dir.normalize_or_zero()));
            }
        }
        if updates.is_empty() {
            // No outside cell at all: the grid lies inside its part.
            for &i in &missing {
                value[i] = 1.0;
            }
            break;
        }
        for &(i, v, d) in &updates {
            value[i] = v;
            direction[i] = d;
            known[i] = true;
        }
        missing.retain(|&i| !known[i]);
    }
    Finished {
        occlusion: value
            .iter()
            .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect(),
        directions: cones.then(|| {
            direction
                .iter()
                .map(|d| {
                    d.to_array()
                        .map(|c| ((c.clamp(-1.0, 1.0) + 1.0) * 127.5).round() as u8)
                })
                .collect()
        }),
        boundary_max,
        inside: filled,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_of_a_cube_reaches_about_three_times_its_half_size() {
        let cube = [Vec3::splat(-1.0), Vec3::splat(1.0)];
        let g = around(&cube, 0.1, 32);
        // e = 1 + √(4 / 0.4π) = 2.78 (the paper: "about 3 r").
        assert!((g.half.x - 2.784).abs() < 1e-3, "{}", g.half);
        assert_eq!(g.half.x, g.half.z);
        let m = g.grid_from_bind();
        assert!(
            m.transform_point3(g.centre - g.half)
                .abs_diff_eq(Vec3::ZERO, 1e-6)
        );
        assert!(
            m.transform_point3(g.centre + g.half)
                .abs_diff_eq(Vec3::ONE, 1e-6)
        );
        let c = m.transform_point3(g.cell_centre(0, 31, 5));
        assert!(c.abs_diff_eq(Vec3::new(0.5, 31.5, 5.5) / 32.0, 1e-6), "{c}");
        // A flat part still gets depth from its area.
        let flat = around(
            &[Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 0.0, 1.0)],
            0.1,
            8,
        );
        assert!((flat.half.y - (4.0 / (0.4 * std::f32::consts::PI)).sqrt()).abs() < 1e-4);
    }

    #[test]
    fn finishing_rescales_to_zero_on_the_boundary_and_fills_the_inside() {
        let n = 5;
        let mut cells = vec![
            RawCell {
                occlusion: 0.2,
                direction: Vec3::X,
                inside: false,
            };
            n * n * n
        ];
        let at = |x: usize, y: usize, z: usize| (z * n + y) * n + x;
        cells[at(2, 2, 2)] = RawCell {
            occlusion: 1.0,
            direction: Vec3::ZERO,
            inside: true,
        };
        cells[at(2, 2, 1)].occlusion = 0.6;
        let f = finish(&cells, n, true);
        assert_eq!(f.boundary_max, 0.2);
        assert_eq!(f.inside, 1);
        assert_eq!(f.occlusion[at(0, 0, 0)], 0);
        // (0.6 − 0.2) / 0.8 = 0.5.
        assert_eq!(f.occlusion[at(2, 2, 1)], 128);
        // The centre: the mean of its 26 neighbours, 25 at 0 and one at ½.
        assert_eq!(
            f.occlusion[at(2, 2, 2)],
            (0.5 / 26.0 * 255.0f32).round() as u8
        );
        assert_eq!(f.directions.unwrap()[at(2, 2, 2)], [255, 128, 128]);
    }

    #[test]
    fn a_slab_survives_its_blob_and_a_bad_one_is_refused() {
        let slab = Slab {
            part: 3,
            resolution: 2,
            first: 1,
            cells: (0..4)
                .map(|i| RawCell {
                    occlusion: i as f32 / 4.0,
                    direction: Vec3::Y,
                    inside: i == 2,
                })
                .collect(),
        };
        let bytes = slab.to_bytes();
        assert_eq!(Slab::from_bytes(&bytes, 2).unwrap(), slab);
        assert!(Slab::from_bytes(&bytes, 4).is_err());
        assert!(Slab::from_bytes(&bytes[..bytes.len() - 1], 2).is_err());
    }
}
