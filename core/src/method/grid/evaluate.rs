//! How good a grid bake is (DESIGN §6), against ray-traced ground truth of
//! the whole posed object on clip frames the bake never looked at:
//!
//! * **receivers**: every vertex of every part (its posed normal; the
//!   whole object occludes, as a vertex bake would trace it) and points on
//!   a ground plane at the lowest vertex under the object (normal up; the
//!   ground itself occludes nothing, so the truth is what the parts cast);
//!   ground points with a surface straight above within a hair (under a
//!   tyre's contact) are left out and counted;
//! * **frames**: random times of the test clips, another seed than the
//!   static average's frames of the training clips;
//! * **variants**: the grids as engines use them (with and without cones),
//!   each part's grid alone (no occlusion between parts), each part's
//!   exact self-occlusion (traced on the part alone: a rigid part's never
//!   changes) with and without the other parts' grids, the static
//!   average (per receiver, the mean truth over the training frames), and
//!   the product form: the grids' change on a static base fitted to those
//!   frames ([`GridModel::ao`]).

use glam::{Mat4, Vec3};
use rand::{RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{
    GridOptions,
    base::Receiver,
    model::{GridModel, PartPose, Terms},
    parts::Part,
};
use crate::{
    Character, Clip,
    asset::metrics::{Errors, FrameError},
    rig::pose::Pose,
    trace::{
        Scene, SceneOptions, SurfaceMesh, SurfaceParams, TraceError, no_progress,
        surface_occlusion, vertex_occlusion,
    },
};

/// Ground points with a surface this close straight above (a fraction of
/// the object's diagonal) are under its contact.
pub const CONTACT: f32 = 0.005;

/// Seeds of the evaluation ("grideval", "gridavrg", "gridnois").
const EVAL_SEED: u64 = 0x6772_6964_6576_616c;
const AVERAGE_SEED: u64 = 0x6772_6964_6176_7267;
const NOISE_SEED: u64 = 0x6772_6964_6e6f_6973;

/// A clip frame: the clip (an index into the bake's clips; `None`: the
/// rest pose of a character without clips) and the time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Frame {
    /// The clip.
    pub clip: Option<usize>,
    /// Seconds into it.
    pub time: f32,
}

impl Frame {
    /// The pose at this frame.
    pub fn pose(&self, character: &Character, clips: &[Clip]) -> Pose {
        match self.clip {
            Some(c) => Pose::sample(&character.skeleton, &clips[c], self.time),
            None => Pose::rest(&character.skeleton),
        }
    }
}

/// `count` random frames of `clips` (indices into `all`), seeded.
pub fn random_frames(all: &[Clip], clips: &[usize], count: usize, seed: u64) -> Vec<Frame> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| match clips {
            [] => Frame {
                clip: None,
                time: 0.0,
            },
            _ => {
                let c = clips[rng.random_range(0..clips.len())];
                Frame {
                    clip: Some(c),
                    time: rng.random_range(0.0..1.0f32) * all[c].duration,
                }
            }
        })
        .collect()
}

/// Occlusion at every receiver of one frame.
#[derive(Debug, Clone, Default)]
pub struct Values {
    /// At each vertex.
    pub vertices: Vec<f32>,
    /// At each ground point.
    pub ground: Vec<f32>,
}

/// A variant's prediction at a frame: its vertex values, then its ground
/// values.
pub type Predictor<'a> = dyn Fn(&FrameTruth) -> (Vec<f32>, Vec<f32>) + Sync + 'a;

/// One frame's receivers and their truth.
#[derive(Debug, Clone)]
pub struct FrameTruth {
    /// The frame.
    pub frame: Frame,
    /// Palette matrices (`world_from_bind`).
    pub palette: Vec<Mat4>,
    /// Posed vertex positions.
    pub positions: Vec<Vec3>,
    /// Posed vertex normals.
    pub normals: Vec<Vec3>,
    /// Surface AO at each vertex.
    pub vertices: Vec<f32>,
    /// Surface AO at each ground point.
    pub ground: Vec<f32>,
    /// Which vertices draw something in the frame
    /// (`Character::drawn_vertices`): only they are judged.
    pub drawn: Vec<bool>,
}

/// The ground truth of an evaluation and the references it needs.
#[derive(Debug, Clone)]
pub struct GroundTruth {
    /// The evaluated frames.
    pub frames: Vec<FrameTruth>,
    /// The ground points (one plane for every frame).
    pub ground: Vec<Vec3>,
    /// Whether each ground point is seen (not under a contact in any
    /// evaluated frame).
    pub ground_seen: Vec<bool>,
    /// The vertices each part carries (the receivers on parts).
    pub owner: Vec<Option<usize>>,
    /// Each vertex's occlusion by its own part alone.
    pub self_ao: Vec<f32>,
    /// The static average: mean truth over the training frames, per
    /// vertex, then per ground point.
    pub average: (Vec<f32>, Vec<f32>),
    /// RMSE of one truth estimate at the vertices and on the ground (the
    /// first frame traced again with independent rays, the difference
    /// over √2): what a perfect model would still score.
    pub noise_rmse: (f64, f64),
    /// Rays traced.
    pub rays: u64,
}

/// What the evaluation traces with.
#[derive(Debug, Clone, Copy)]
pub struct Inputs<'a> {
    /// The character.
    pub character: &'a Character,
    /// All the bake's clips.
    pub clips: &'a [Clip],
    /// Its training clips (the static average's frames).
    pub train: &'a [usize],
    /// Its test clips (the evaluated frames).
    pub test: &'a [usize],
    /// The parts.
    pub parts: &'a [Part],
    /// The options.
    pub options: &'a GridOptions,
    /// The distance limit of the truth (the grids' own).
    pub max_distance: f32,
    /// The bake's seed.
    pub seed: u64,
}

struct Traced {
    vertices: Vec<f32>,
    ground: Vec<f32>,
    scene: Scene,
    palette: Vec<Mat4>,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    drawn: Vec<bool>,
}

impl Traced {
    /// The frame's receivers and their truth (the BVH dropped).
    fn truth(self, frame: Frame) -> FrameTruth {
        FrameTruth {
            frame,
            palette: self.palette,
            positions: self.positions,
            normals: self.normals,
            vertices: self.vertices,
            ground: self.ground,
            drawn: self.drawn,
        }
    }
}

impl Inputs<'_> {
    /// The static average's frames (of the training clips), which the
    /// static base is fitted to.
    pub fn training_frames(&self) -> Vec<Frame> {
        random_frames(
            self.clips,
            self.train,
            self.options.average_frames,
            self.seed ^ AVERAGE_SEED,
        )
    }

    /// The truth of `frames` at the vertices and at `ground` (normal up),
    /// traced side by side with the bake's seed, as the static average's
    /// frames are.
    pub fn trace_frames(
        &self,
        frames: &[Frame],
        ground: &[Vec3],
    ) -> Result<Vec<Values>, TraceError> {
        self.trace_frames_at(frames, ground, true)
    }

    /// [`Self::trace_frames`], the vertices left out (empty) unless
    /// `at_vertices`.
    fn trace_frames_at(
        &self,
        frames: &[Frame],
        ground: &[Vec3],
        at_vertices: bool,
    ) -> Result<Vec<Values>, TraceError> {
        frames
            .par_iter()
            .map(|frame| {
                let t = self.trace_at(frame, ground, self.seed, at_vertices)?;
                Ok(Values {
                    vertices: t.vertices,
                    ground: t.ground,
                })
            })
            .collect()
    }

    fn surface(&self, seed: u64) -> SurfaceParams {
        self.options.truth(self.max_distance, seed)
    }

    fn trace(&self, frame: &Frame, ground: &[Vec3], seed: u64) -> Result<Traced, TraceError> {
        self.trace_at(frame, ground, seed, true)
    }

    /// [`Self::trace`], the vertices' truth left out (empty) unless
    /// `at_vertices`.
    fn trace_at(
        &self,
        frame: &Frame,
        ground: &[Vec3],
        seed: u64,
        at_vertices: bool,
    ) -> Result<Traced, TraceError> {
        let c = self.character;
        let pose = frame.pose(c, self.clips);
        let posed = c.skin(&pose);
        let scene = Scene::new(&posed.positions, &c.triangles, &SceneOptions::default())?;
        let params = self.surface(seed);
        let vertices = if at_vertices {
            vertex_occlusion(
                &scene,
                &SurfaceMesh {
                    positions: &posed.positions,
                    normals: &posed.normals,
                    triangles: &c.triangles,
                },
                &params,
                &no_progress,
            )?
        } else {
            Vec::new()
        };
        let up = vec![Vec3::Y; ground.len()];
        let ground = surface_occlusion(&scene, ground, &up, &params, &no_progress)?;
        Ok(Traced {
            vertices,
            ground,
            scene,
            palette: c.joint_matrices(&pose),
            drawn: c.drawn_vertices(&posed.positions),
            positions: posed.positions,
            normals: posed.normals,
        })
    }

    /// Each vertex's occlusion by its own part alone, in bind space.
    fn self_occlusion(&self) -> Result<Vec<f32>, TraceError> {
        let c = self.character;
        let mut out = vec![0.0; c.vertex_count()];
        // Each part on its own thread, written in the parts' order.
        let traced: Vec<(Vec<u32>, Vec<f32>)> = self
            .parts
            .par_iter()
            .map(|part| {
                let (globals, positions, triangles) = part.mesh(c);
                let normals: Vec<Vec3> = globals.iter().map(|&v| c.normals[v as usize]).collect();
                let scene = Scene::new(&positions, &triangles, &SceneOptions::default())?;
                let values = vertex_occlusion(
                    &scene,
                    &SurfaceMesh {
                        positions: &positions,
                        normals: &normals,
                        triangles: &triangles,
                    },
                    &self.surface(self.seed ^ EVAL_SEED),
                    &no_progress,
                )?;
                let own: (Vec<u32>, Vec<f32>) = globals
                    .iter()
                    .zip(&values)
                    .filter(|(v, _)| part.vertices.binary_search(*v).is_ok())
                    .map(|(&v, &a)| (v, a))
                    .unzip();
                Ok(own)
            })
            .collect::<Result<_, TraceError>>()?;
        for (vertices, values) in traced {
            for (v, a) in vertices.into_iter().zip(values) {
                out[v as usize] = a;
            }
        }
        Ok(out)
    }
}

impl GroundTruth {
    /// Draws the frames and the ground (seeded by `inputs.seed`) and
    /// traces them. `training_vertices`, when given, is the truth of the
    /// static average's frames at the vertices (frame after frame) as
    /// [`Inputs::trace_frames`] traced it for the static base's `sample`
    /// jobs: the same values, so they are not traced again (only the
    /// ground is, at this evaluation's points).
    pub fn trace(
        inputs: &Inputs<'_>,
        training_vertices: Option<&[f32]>,
    ) -> Result<Self, TraceError> {
        let o = inputs.options;
        let c = inputs.character;
        let seed = inputs.seed;
        let eval = random_frames(inputs.clips, inputs.test, o.eval_frames, seed ^ EVAL_SEED);
        let average = inputs.training_frames();
        // The ground: a disc under every frame's vertices, at the lowest.
        let all: Vec<Frame> = eval.iter().chain(&average).copied().collect();
        let (lo, hi) = super::static_base::bounds(c, inputs.clips, &all);
        let (centre, radius) = super::static_base::ground_disc(lo, hi);
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ EVAL_SEED ^ 1);
        let mut ground = Vec::with_capacity(o.eval_ground);
        while ground.len() < o.eval_ground {
            let (x, z) = (
                rng.random_range(-1.0..1.0f32),
                rng.random_range(-1.0..1.0f32),
            );
            if x * x + z * z <= 1.0 {
                ground.push(Vec3::new(
                    centre.x + radius * x,
                    lo.y,
                    centre.z + radius * z,
                ));
            }
        }
        let reach = CONTACT * (hi - lo).length();
        let held_out = seed ^ crate::trace::HELD_OUT_SEED;
        // The frames are traced side by side (each its own skinning and
        // BVH, the serial part of a small mesh's trace) and gathered in
        // order: the same values on any number of threads. A frame's BVH
        // is dropped once it has said which ground points it touches.
        let traced: Vec<(FrameTruth, Vec<bool>)> = eval
            .par_iter()
            .map(|frame| {
                let t = inputs.trace(frame, &ground, held_out)?;
                let near: Vec<bool> = ground
                    .iter()
                    .map(|&p| t.scene.surface_near(p, Vec3::Y, reach))
                    .collect();
                Ok((t.truth(*frame), near))
            })
            .collect::<Result<_, TraceError>>()?;
        let mut ground_seen = vec![true; ground.len()];
        let mut frames = Vec::with_capacity(eval.len());
        for (truth, near) in traced {
            for (seen, near) in ground_seen.iter_mut().zip(near) {
                *seen &= !near;
            }
            frames.push(truth);
        }
        let mut noise_rmse = (0.0, 0.0);
        if let (Some(frame), Some(first)) = (eval.first(), frames.first()) {
            let again = inputs.trace(frame, &ground, seed ^ NOISE_SEED)?;
            noise_rmse = (
                rmse(&first.vertices, &again.vertices) / 2f64.sqrt(),
                rmse(&first.ground, &again.ground) / 2f64.sqrt(),
            );
        }
        let vertices = c.vertex_count();
        if let Some(v) = training_vertices.filter(|v| v.len() != average.len() * vertices) {
            return Err(TraceError::Invalid(format!(
                "the static average's vertex truth holds {} values, not {} frames × {vertices} vertices",
                v.len(),
                average.len()
            )));
        }
        let known = training_vertices;
        let training = match known {
            Some(known) => inputs
                .trace_frames_at(&average, &ground, false)?
                .into_iter()
                .zip(known.chunks_exact(vertices.max(1)))
                .map(|(traced, v)| Values {
                    vertices: v.to_vec(),
                    ground: traced.ground,
                })
                .collect(),
            None => inputs.trace_frames(&average, &ground)?,
        };
        let mean = mean_of(&training);
        let static_average = (mean.vertices, mean.ground);
        let self_ao = inputs.self_occlusion()?;
        let at_vertices =
            (eval.len() + 1 + if known.is_some() { 0 } else { average.len() } + 1) as u64;
        let at_ground = (eval.len() + average.len() + 1) as u64;
        let rays = (at_vertices * vertices as u64 + at_ground * ground.len() as u64)
            * u64::from(o.eval_rays);
        Ok(Self {
            frames,
            ground,
            ground_seen,
            owner: super::parts::owners(inputs.parts, c.vertex_count()),
            self_ao,
            average: static_average,
            noise_rmse,
            rays,
        })
    }

    /// Ground points left out (under a contact).
    pub fn ground_hidden(&self) -> usize {
        self.ground_seen.iter().filter(|&&s| !s).count()
    }

    /// The errors of `predict` (per frame: its vertex values, then its
    /// ground values) against the truth: (at the vertices of parts, on
    /// the ground).
    pub fn errors(&self, predict: &Predictor<'_>) -> (Errors, Errors) {
        let frames: Vec<(FrameError, FrameError)> = self
            .frames
            .par_iter()
            .map(|f| {
                let (v, g) = predict(f);
                let (vp, vt): (Vec<f32>, Vec<f32>) = (0..v.len())
                    .filter(|&i| self.owner[i].is_some() && f.drawn[i])
                    .map(|i| (v[i], f.vertices[i]))
                    .unzip();
                let (gp, gt): (Vec<f32>, Vec<f32>) = (0..g.len())
                    .filter(|&i| self.ground_seen[i])
                    .map(|i| (g[i], f.ground[i]))
                    .unzip();
                (FrameError::of(&vp, &vt), FrameError::of(&gp, &gt))
            })
            .collect();
        let (v, g): (Vec<_>, Vec<_>) = frames.into_iter().unzip();
        (Errors::of(&v), Errors::of(&g))
    }

    /// `vertex(index, position, normal, part)` at every vertex of a frame
    /// and `ground(point)` at every ground point.
    fn at_receivers(
        &self,
        frame: &FrameTruth,
        vertex: impl Fn(usize, Vec3, Vec3, Option<usize>) -> f32,
        ground: impl Fn(Vec3) -> f32,
    ) -> (Vec<f32>, Vec<f32>) {
        let vertices = frame
            .positions
            .iter()
            .zip(&frame.normals)
            .enumerate()
            .map(|(i, (&p, &n))| vertex(i, p, n, self.owner[i]))
            .collect();
        (vertices, self.ground.iter().map(|&p| ground(p)).collect())
    }

    /// A grid model's prediction at a frame's receivers, from the parts
    /// `terms` names; with `exact_self`, each vertex's own part is its
    /// traced self-occlusion instead of its grid.
    pub fn predict(
        &self,
        model: &GridModel,
        frame: &FrameTruth,
        terms: Terms,
        exact_self: bool,
    ) -> (Vec<f32>, Vec<f32>) {
        let poses: Vec<PartPose> = model.poses(&frame.palette);
        self.at_receivers(
            frame,
            |i, p, n, own| {
                if !exact_self {
                    return model.occlusion(&poses, p, n, own, terms);
                }
                let others = model.occlusion(&poses, p, n, own, Terms::Others);
                match terms {
                    Terms::Own => self.self_ao[i],
                    _ => 1.0 - (1.0 - self.self_ao[i]) * (1.0 - others),
                }
            },
            |p| match terms {
                Terms::Own => 0.0,
                _ => model.occlusion(&poses, p, Vec3::Y, None, Terms::All),
            },
        )
    }

    /// What an engine shows with `model` at a frame's receivers
    /// ([`GridModel::ao`]: with a static base, its gains and offsets).
    pub fn predict_ao(&self, model: &GridModel, frame: &FrameTruth) -> (Vec<f32>, Vec<f32>) {
        let poses: Vec<PartPose> = model.poses(&frame.palette);
        self.at_receivers(
            frame,
            |index, p, n, part| model.ao(&poses, p, n, Receiver::Vertex { index, part }),
            |p| model.ao(&poses, p, Vec3::Y, Receiver::Ground),
        )
    }
}

/// The mean over frames of each receiver's value.
pub fn mean_of(frames: &[Values]) -> Values {
    let n = frames.len().max(1) as f64;
    let mean = |values: fn(&Values) -> &Vec<f32>| -> Vec<f32> {
        let len = frames.first().map_or(0, |f| values(f).len());
        (0..len)
            .map(|i| (frames.iter().map(|f| f64::from(values(f)[i])).sum::<f64>() / n) as f32)
            .collect()
    };
    Values {
        vertices: mean(|f| &f.vertices),
        ground: mean(|f| &f.ground),
    }
}

impl GroundTruth {
    /// Nanoseconds per receiver of `model`'s lookup at every receiver of a
    /// frame, on one thread: the median over the frames.
    pub fn lookup_cost(&self, model: &GridModel) -> f64 {
        let mut ns: Vec<f64> = self
            .frames
            .iter()
            .map(|f| {
                let started = std::time::Instant::now();
                let (v, g) = self.predict_ao(model, f);
                let n = (v.len() + g.len()).max(1) as f64;
                std::hint::black_box((v, g));
                started.elapsed().as_secs_f64() * 1e9 / n
            })
            .collect();
        ns.sort_by(f64::total_cmp);
        ns.get(ns.len() / 2).copied().unwrap_or(0.0)
    }
}

fn rmse(a: &[f32], b: &[f32]) -> f64 {
    let n = a.len().max(1) as f64;
    let se: f64 = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
        .sum();
    (se / n).sqrt()
}

/// One variant's figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridVariant {
    /// Its name, such as `grids (cones)`.
    pub name: String,
    /// What it is.
    pub description: String,
    /// Bytes a renderer keeps for it.
    pub bytes: usize,
    /// Against the truth at the vertices of the parts.
    pub vertices: Errors,
    /// Against the truth on the ground plane.
    pub ground: Errors,
}

/// A grid bake's evaluation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridEvaluation {
    /// The evaluated frames, as (clip name, seconds).
    pub frames: Vec<(Option<String>, f32)>,
    /// Receivers on parts per frame.
    pub vertices: usize,
    /// Ground points per frame.
    pub ground_points: usize,
    /// Ground points left out (under a contact).
    pub ground_hidden: usize,
    /// Rays per ground-truth point.
    pub rays_per_point: u32,
    /// The truth's distance limit (`aobake trace --max-distance` gives
    /// the same quantity).
    pub max_distance: f32,
    /// RMSE of one truth estimate at the vertices.
    pub noise_rmse_vertices: f64,
    /// RMSE of one truth estimate on the ground.
    pub noise_rmse_ground: f64,
    /// Every variant, the baked one first.
    pub variants: Vec<GridVariant>,
    /// Run-time cost of the baked model on this machine's CPU: nanoseconds
    /// per receiver of one thread's lookup over every part (the median of
    /// the evaluated frames).
    pub lookup_ns_per_receiver: f64,
}
