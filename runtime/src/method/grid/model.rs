//! A baked grid set at run time (Malmer et al. §3–5): each part's cells
//! looked up trilinearly through the part's pose, turned into the
//! occlusion a receiver gets, and combined over the parts.
//!
//! For a receiver at `p` with unit normal `n`:
//!
//! * the part's grid is looked up at `grid_from_world · p` (texture
//!   convention: cell centres at (i + ½)/n, clamped to the edge cells
//!   inside the box, nothing outside it), giving the stored
//!   ao_grid = 2·ao′ and, with cones, the axis d;
//! * **without cones** (§4) another part casts a = min(1, ao_grid) and the
//!   receiver's own part a = max(0, (ao_grid − 1)/2) (the self-occlusion
//!   rule of §4.2);
//! * **with cones** (§5.1) every part, its own included, casts
//!   a = T_clip(ao′, d·n): the cone clipped by the tangent plane;
//! * the parts combine as 1 − Π(1 − aᵢ) (§3.2; with cones this is §5.2.1's
//!   simple blending, whose occlusion is the same product);
//! * with a static base (aobake's product form, [`super::base`]), the
//!   combined occlusion is scaled by the receiver's gain and its static
//!   offset added: [`GridModel::ao`].
//!
//! `shaders/wgsl/grid_ao.wgsl` is the same function for engines; a worker
//! test holds the two together.

use crate::method::Method;
use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};

use super::{
    GridBox,
    base::{Receiver, StaticBase},
    tclip::TClip,
};

/// One part's baked grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartGrid {
    /// The part's name (its node's).
    pub name: String,
    /// The palette entry whose `world_from_bind` moves it.
    pub joint: usize,
    /// That entry's node.
    pub node: usize,
    /// Where the grid sits in bind space.
    pub grid: GridBox,
    /// V_M, the boundary maximum the cells were rescaled by.
    pub boundary_max: f32,
    /// Cells found inside the part and filled from their neighbours.
    pub inside: usize,
    /// One byte per cell, x fastest: ao_grid = 2·b/255.
    #[serde(skip)]
    pub occlusion: Vec<u8>,
    /// With cones, three bytes per cell: the axis, d = 2·b/255 − 1 (bind
    /// space).
    #[serde(skip)]
    pub directions: Option<Vec<[u8; 3]>>,
}

/// Where a part is in one frame: what a renderer uploads per part.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PartPose {
    /// World space to grid space ([0, 1]³ is the grid).
    pub grid_from_world: Mat4,
    /// The part's palette matrix: bind space to world (turns cone axes).
    pub world_from_bind: Mat4,
}

/// Which parts a receiver is shaded by (the evaluation's variants; engines
/// use [`Terms::All`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Terms {
    /// Every part, its own by the self-occlusion rule.
    All,
    /// Its own part only: no occlusion between parts.
    Own,
    /// Every part but its own.
    Others,
}

/// A baked grid set.
#[derive(Debug, Clone, PartialEq)]
pub struct GridModel {
    /// The parts, in palette order.
    pub parts: Vec<PartGrid>,
    /// With cones, `T_clip`.
    pub tclip: Option<TClip>,
    /// The static base (aobake's product form); `None`: the paper's
    /// grids alone.
    pub base: Option<StaticBase>,
}

/// A trilinear sample of one grid: ao′ (0..1) and the unnormalised axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// The rescaled occluded fraction of the sphere, ao′ = ao_grid / 2.
    pub fraction: f32,
    /// The interpolated axis (bind space), not normalised.
    pub axis: Vec3,
}

impl PartGrid {
    /// The trilinear sample at grid-space `g`, `None` outside [0, 1]³.
    pub fn sample(&self, g: Vec3) -> Option<Sample> {
        if g.cmplt(Vec3::ZERO).any() || g.cmpgt(Vec3::ONE).any() {
            return None;
        }
        let n = self.grid.resolution;
        let last = (n - 1) as f32;
        let s = (g * n as f32 - 0.5).clamp(Vec3::ZERO, Vec3::splat(last));
        let i0 = s.floor().min(Vec3::splat(last - 1.0));
        let f = s - i0;
        let (x, y, z) = (i0.x as usize, i0.y as usize, i0.z as usize);
        let mut fraction = 0.0f32;
        let mut axis = Vec3::ZERO;
        for (dz, wz) in [(0, 1.0 - f.z), (1, f.z)] {
            for (dy, wy) in [(0, 1.0 - f.y), (1, f.y)] {
                for (dx, wx) in [(0, 1.0 - f.x), (1, f.x)] {
                    let i = ((z + dz) * n + (y + dy)) * n + (x + dx);
                    let w = wx * wy * wz;
                    fraction += w * (f32::from(self.occlusion[i]) / 255.0);
                    if let Some(d) = &self.directions {
                        let d = Vec3::from(d[i].map(|b| f32::from(b) / 255.0 * 2.0 - 1.0));
                        axis += w * d;
                    }
                }
            }
        }
        Some(Sample { fraction, axis })
    }

    /// Bytes a renderer keeps for this part.
    pub fn bytes(&self) -> usize {
        self.occlusion.len() * if self.directions.is_some() { 4 } else { 1 }
    }

    /// The part's pose from its palette matrix.
    pub fn pose(&self, world_from_bind: Mat4) -> PartPose {
        PartPose {
            grid_from_world: self.grid.grid_from_bind() * world_from_bind.inverse(),
            world_from_bind,
        }
    }
}

impl GridModel {
    /// The method.
    pub fn method(&self) -> Method {
        Method::Grid
    }

    /// Whether the cones are baked.
    pub fn cones(&self) -> bool {
        self.tclip.is_some()
    }

    /// Bytes a renderer keeps: every part's cells, the table and the
    /// base's f16 offsets.
    pub fn bytes(&self) -> usize {
        self.parts.iter().map(PartGrid::bytes).sum::<usize>()
            + self.tclip.as_ref().map_or(0, |t| 8 * t.values.len())
            + self.base.as_ref().map_or(0, |b| {
                2 * (b.vertex_offsets.len() + b.ground.offsets.len()) + 4 * b.part_gains.len()
            })
    }

    /// Every part's pose from the palette matrices of a frame
    /// (`Character::joint_matrices`).
    pub fn poses(&self, palette: &[Mat4]) -> Vec<PartPose> {
        self.parts
            .iter()
            .map(|p| p.pose(palette[p.joint]))
            .collect()
    }

    /// The occlusion part `k` casts on a receiver at `p` (world) with unit
    /// normal `n`; `own` says whether `k` is the receiver's part.
    pub fn part_occlusion(&self, k: usize, pose: &PartPose, p: Vec3, n: Vec3, own: bool) -> f32 {
        let part = &self.parts[k];
        let Some(s) = part.sample(pose.grid_from_world.transform_point3(p)) else {
            return 0.0;
        };
        let ao_grid = 2.0 * s.fraction;
        match (&self.tclip, &part.directions) {
            (Some(t), Some(_)) => {
                let d = pose
                    .world_from_bind
                    .transform_vector3(s.axis)
                    .normalize_or_zero();
                t.lookup(s.fraction, d.dot(n))[0]
            }
            _ if own => ((ao_grid - 1.0) * 0.5).max(0.0),
            _ => ao_grid.min(1.0),
        }
    }

    /// The occlusion at a receiver `p` with unit normal `n` on part `own`
    /// (`None`: a receiver of no part, such as the ground), from the parts
    /// `terms` names, combined as 1 − Π(1 − aᵢ).
    pub fn occlusion(
        &self,
        poses: &[PartPose],
        p: Vec3,
        n: Vec3,
        own: Option<usize>,
        terms: Terms,
    ) -> f32 {
        let mut open = 1.0f32;
        for (k, pose) in poses.iter().enumerate() {
            let is_own = own == Some(k);
            let wanted = match terms {
                Terms::All => true,
                Terms::Own => is_own,
                Terms::Others => !is_own,
            };
            if wanted {
                open *= 1.0 - self.part_occlusion(k, pose, p, n, is_own);
            }
        }
        1.0 - open
    }

    /// The static base's offset for `receiver` at `p` (0 without a base):
    /// what the GPU lookups (`grid_ao`) are given per receiver.
    pub fn offset(&self, receiver: Receiver, p: Vec3) -> f32 {
        self.base.as_ref().map_or(0.0, |b| b.offset(receiver, p))
    }

    /// The occlusion an engine shows at `receiver`, at `p` with unit
    /// normal `n`: every part's grid combined
    /// ([`Self::occlusion`] with [`Terms::All`]) and, with a base, scaled
    /// by the receiver's gain with its static offset added, clamped to
    /// [0, 1].
    pub fn ao(&self, poses: &[PartPose], p: Vec3, n: Vec3, receiver: Receiver) -> f32 {
        let own = match receiver {
            Receiver::Vertex { part, .. } | Receiver::Other { part } => part,
            Receiver::Ground => None,
        };
        let grids = self.occlusion(poses, p, n, own, Terms::All);
        match &self.base {
            Some(base) => {
                let (gain, offset) = base.terms(receiver, p);
                (gain * grids + offset).clamp(0.0, 1.0)
            }
            None => grids,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn part(n: usize, value: impl Fn(usize, usize, usize) -> u8) -> PartGrid {
        let mut occlusion = Vec::new();
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    occlusion.push(value(x, y, z));
                }
            }
        }
        PartGrid {
            name: "p".into(),
            joint: 0,
            node: 0,
            grid: GridBox {
                centre: Vec3::ZERO,
                half: Vec3::ONE,
                resolution: n,
            },
            boundary_max: 0.0,
            inside: 0,
            occlusion,
            directions: None,
        }
    }

    #[test]
    fn the_lookup_is_trilinear_between_cell_centres_and_empty_outside() {
        let p = part(4, |x, _, _| (x * 50) as u8);
        // Cell centres at (i + ½)/4: halfway between cells 1 and 2 in x.
        let s = p.sample(Vec3::new(0.5, 0.3, 0.9)).unwrap();
        assert!((s.fraction - 75.0 / 255.0).abs() < 1e-6);
        // Clamped to the edge cell between the boundary and its centre.
        let s = p.sample(Vec3::new(0.01, 0.5, 0.5)).unwrap();
        assert_eq!(s.fraction, 0.0);
        assert!(p.sample(Vec3::new(1.01, 0.5, 0.5)).is_none());
    }

    #[test]
    fn parts_combine_multiplicatively_and_the_own_part_by_the_self_rule() {
        let a = part(2, |_, _, _| 51); // ao_grid = 0.4
        let b = part(2, |_, _, _| 153); // ao_grid = 1.2
        let model = GridModel {
            parts: vec![a.clone(), b],
            tclip: None,
            base: None,
        };
        let poses = model.poses(&[Mat4::IDENTITY, Mat4::IDENTITY]);
        let at = |own, terms| model.occlusion(&poses, Vec3::ZERO, Vec3::Y, own, terms);
        // Ground: 1 − (1 − 0.4)(1 − 1) = 1.
        assert!((at(None, Terms::All) - 1.0).abs() < 1e-6);
        // On part 1: its own by (1.2 − 1)/2 = 0.1, the other 0.4.
        assert!((at(Some(1), Terms::All) - (1.0 - 0.6 * 0.9)).abs() < 1e-5);
        assert!((at(Some(1), Terms::Own) - 0.1).abs() < 1e-5);
        assert!((at(Some(1), Terms::Others) - 0.4).abs() < 1e-5);
        // A part moved away casts nothing.
        let moved = model.poses(&[Mat4::from_translation(Vec3::X * 5.0), Mat4::IDENTITY]);
        let v = model.occlusion(&moved, Vec3::ZERO, Vec3::Y, Some(1), Terms::Others);
        assert_eq!(v, 0.0);
    }

    #[test]
    fn the_static_base_scales_the_grids_and_adds_each_receivers_offset() {
        use crate::method::grid::base::{GroundBase, GroundSquare, StaticBase};
        let model = GridModel {
            parts: vec![part(2, |_, _, _| 51), part(2, |_, _, _| 153)],
            tclip: None,
            base: Some(StaticBase {
                vertex_offsets: vec![0.25, -0.5],
                part_gains: vec![0.5, 2.0],
                ground: GroundBase {
                    square: GroundSquare {
                        min: [-1.0, -1.0],
                        size: 2.0,
                        height: 0.0,
                        resolution: 1,
                    },
                    gain: 0.75,
                    offsets: vec![0.125],
                },
            }),
        };
        let poses = model.poses(&[Mat4::IDENTITY, Mat4::IDENTITY]);
        let ao = |r| model.ao(&poses, Vec3::ZERO, Vec3::Y, r);
        let on_1 = model.occlusion(&poses, Vec3::ZERO, Vec3::Y, Some(1), Terms::All);
        let vertex = |index, part| Receiver::Vertex { index, part };
        assert!((ao(vertex(0, Some(1))) - (2.0 * on_1 + 0.25).min(1.0)).abs() < 1e-6);
        let on_0 = model.occlusion(&poses, Vec3::ZERO, Vec3::Y, Some(0), Terms::All);
        assert!((ao(vertex(1, Some(0))) - (0.5 * on_0 - 0.5).max(0.0)).abs() < 1e-6);
        // The ground (and a vertex of no part) take the ground's gain.
        let open = model.occlusion(&poses, Vec3::ZERO, Vec3::Y, None, Terms::All);
        assert!((ao(Receiver::Ground) - (0.75 * open + 0.125).min(1.0)).abs() < 1e-6);
        // Any other surface: the grids alone.
        assert_eq!(ao(Receiver::Other { part: None }), open.min(1.0));
        assert_eq!(ao(Receiver::Other { part: Some(1) }), on_1.min(1.0));
        assert_eq!(model.offset(Receiver::Ground, Vec3::ZERO), 0.125);
        assert_eq!(model.offset(vertex(1, None), Vec3::ZERO), -0.5);
        // Without a base, the grids alone.
        let paper = GridModel {
            base: None,
            ..model.clone()
        };
        assert_eq!(
            paper.ao(
                &paper.poses(&[Mat4::IDENTITY; 2]),
                Vec3::ZERO,
                Vec3::Y,
                Receiver::Ground
            ),
            open
        );
    }
}
