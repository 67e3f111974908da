//! Who casts the rays: the CPU tracer here, or a [`RayEngine`] installed by
//! the process (the worker's wgpu compute tracer, `aobake_worker::gpu::
//! GpuTracer`).
//!
//! Every estimator reduces a point's rays to a [`Tally`] (hits, back-face
//! hits, a weighted sum, a sum of hit directions), and turns the tally into
//! its value in one place, whoever traced the rays. An engine is given a
//! [`RayBatch`]: the scenes (posed meshes, several per batch so that one
//! dispatch traces many poses), the points with their ray frames and
//! scrambling seeds, the estimator and the ray count; it returns one tally
//! per point. The directions are those of `trace::sampling`, so an engine
//! that casts the same rays through the same arithmetic gets the same hits
//! except at float ties.
//!
//! The engine is process-wide ([`set_engine`]): the tracer is a property of
//! the machine a job runs on, like its core count, not of the bake.

use std::sync::{Arc, RwLock};

use glam::Vec3A;

pub use super::sampling::sobol_directions;
use super::{Scene, TraceError};

/// What a point's rays estimate, and how a hit counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Estimator {
    /// Cosine-weighted about the normal: count the rays that meet a surface
    /// within the maximum distance (any hit).
    Cosine,
    /// Cosine-weighted about the normal: sum e^(−τt) over the closest hits
    /// within the maximum distance; `tau` per model unit.
    CosineExponential {
        /// τ, per model unit.
        tau: f32,
    },
    /// Uniform on the sphere, closest hit without a limit: count hits
    /// within the maximum distance and their directions' sum, and the rays
    /// whose first hit is a back face (Malmer et al. Eq. 5).
    Volume,
    /// Uniform on the sphere, closest hit without a limit: sum
    /// max(0, n·ω)·(1 − t/D_max)^α over hits within D_max (the maximum
    /// distance), and count back-face hits (Kroon Eq. 3.1).
    Kroon {
        /// α, ≥ 0.
        alpha: f32,
        /// Whether the points' normals weight the hits (else the term is
        /// 1).
        facing: bool,
    },
}

impl Estimator {
    /// Whether the directions are cosine-weighted about the normal (else
    /// uniform on the sphere).
    pub fn is_cosine(self) -> bool {
        matches!(
            self,
            Estimator::Cosine | Estimator::CosineExponential { .. }
        )
    }
}

/// One point of a batch: where its rays start and how they are oriented.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayPoint {
    /// Index into [`RayBatch::scenes`].
    pub scene: u32,
    /// Ray origin in the scene's local frame.
    pub origin: Vec3A,
    /// The orthonormal frame of cosine-weighted rays (tangent, bitangent,
    /// normal), or the normal of Kroon's facing term in `normal`; all zero
    /// for a point with no normal.
    pub tangent: Vec3A,
    /// See `tangent`.
    pub bitangent: Vec3A,
    /// See `tangent`.
    pub normal: Vec3A,
    /// The scramble of the point's direction sequence.
    pub seed: u32,
}

/// Points to trace in one go, possibly over several scenes.
#[derive(Debug)]
pub struct RayBatch<'a> {
    /// The scenes the points refer to.
    pub scenes: Vec<&'a Scene>,
    /// The points.
    pub points: Vec<RayPoint>,
    /// What the rays estimate.
    pub estimator: Estimator,
    /// Rays per point.
    pub samples: u32,
    /// Hits farther than this (model units) count as misses; may be
    /// infinite (not for [`Estimator::Kroon`]).
    pub max_distance: f32,
    /// Every point is traced in every scene: `points` hold their origins
    /// in model units (their `scene` is not used), each scene takes them
    /// to its own frame ([`Scene::to_local`]'s arithmetic), and the tallies
    /// come scene by scene (every point in the first scene, then in the
    /// second, …). A cubemap face's time samples share their points so.
    pub shared: bool,
}

impl RayBatch<'_> {
    /// Tallies the batch yields: one per point, or per point and scene
    /// when the points are shared.
    pub fn tallies(&self) -> usize {
        if self.shared {
            self.points.len() * self.scenes.len()
        } else {
            self.points.len()
        }
    }

    /// Checks what every tracer relies on: unless shared, the points come
    /// grouped by scene, in scene order, and name scenes of the batch.
    pub fn check(&self) -> Result<(), TraceError> {
        if self.shared {
            return Ok(());
        }
        let scenes = self.scenes.len() as u32;
        let ordered = self.points.windows(2).all(|w| w[0].scene <= w[1].scene);
        if !ordered || self.points.last().is_some_and(|p| p.scene >= scenes) {
            return Err(TraceError::Invalid(
                "a batch's points are not grouped by scene".into(),
            ));
        }
        Ok(())
    }
}

/// A point's rays reduced: what every estimator's value is made from.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Tally {
    /// Rays that hit within the maximum distance.
    pub hits: u32,
    /// Rays whose closest hit (without the distance limit) is a back face
    /// or the ground from below (sphere estimators only).
    pub back: u32,
    /// The estimator's weighted sum (exponential falloff, Kroon's terms).
    pub sum: f64,
    /// Sum of the directions of the rays that hit within the maximum
    /// distance (the volume estimator).
    pub direction: Vec3A,
}

/// A ray tracer other than the CPU's: it traces whole batches.
pub trait RayEngine: Send + Sync + std::fmt::Debug {
    /// The engine as a person reads it: kind and adapter.
    fn label(&self) -> String;

    /// What the engine has done so far in this process, for a person
    /// (rays, seconds), if it keeps count.
    fn summary(&self) -> Option<String> {
        None
    }

    /// One tally per point of `batch`, in order; `None` when the engine
    /// declines the batch (a scene it cannot take, such as a tree deeper
    /// than its traversal stack), which the CPU then traces. `progress` is
    /// called with the number of points just finished.
    fn trace(
        &self,
        batch: &RayBatch<'_>,
        progress: super::Progress<'_>,
    ) -> Result<Option<Vec<Tally>>, TraceError>;
}

static ENGINE: RwLock<Option<Arc<dyn RayEngine>>> = RwLock::new(None);

/// Installs the process's ray engine (`None`: the CPU tracer, the
/// default). Every estimator of this module traces through it from then
/// on.
pub fn set_engine(engine: Option<Arc<dyn RayEngine>>) {
    *ENGINE.write().unwrap_or_else(|e| e.into_inner()) = engine;
}

/// The process's ray engine, if one is installed.
pub fn engine() -> Option<Arc<dyn RayEngine>> {
    ENGINE.read().unwrap_or_else(|e| e.into_inner()).clone()
}

/// Items (poses, grid layers) a job traces per call of `per_item` points
/// each: with an engine installed, about `points` points (one dispatch,
/// since a single small item leaves most of a GPU idle), between 1 and
/// `max`; on the CPU one, so that the job checkpoints after every item.
pub fn batch_items(per_item: usize, points: usize, max: usize) -> usize {
    if engine().is_some() {
        (points / per_item.max(1)).clamp(1, max.max(1))
    } else {
        1
    }
}

/// The label of the tracer this process uses: `cpu` or the engine's.
pub fn tracer_label() -> String {
    engine().map_or_else(|| "cpu".to_owned(), |e| e.label())
}

/// How a GPU tracer's nodes store their eight child boxes
/// ([`Scene::gpu_nodes`]). Either way the tree and the triangles are the
/// CPU's, and a ray's hits are the same but at float ties: quantised
/// boxes only ever contain the exact ones, so at a given ray length a
/// node enters every child that it enters with exact boxes (perhaps a
/// few more), and the any-hit answer and the closest hit come out the
/// same (only the order of the visits may differ). Bakes use the exact
/// layout; `aobake bench … --tracer gpu-quantised` times the other.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum NodeLayout {
    /// The boxes as f32, [`GPU_NODE_WORDS`] words (256 bytes) a node.
    #[default]
    Exact,
    /// The boxes as bytes on a grid over the node's own box (Ylitie et
    /// al. 2017's compression, rounded outwards), [`GPU_QUANTISED_NODE_WORDS`]
    /// words (96 bytes) a node: fewer bytes fetched per node visited.
    Quantised,
}

impl NodeLayout {
    /// Words per node.
    pub const fn words(self) -> usize {
        match self {
            NodeLayout::Exact => GPU_NODE_WORDS,
            NodeLayout::Quantised => GPU_QUANTISED_NODE_WORDS,
        }
    }
}

/// Words per node of [`Scene::gpu_nodes`] in [`NodeLayout::Exact`].
pub const GPU_NODE_WORDS: usize = 64;
/// Words per node of [`Scene::gpu_nodes`] in [`NodeLayout::Quantised`].
pub const GPU_QUANTISED_NODE_WORDS: usize = 24;
/// Floats per triangle of [`Scene::gpu_triangles`].
pub const GPU_TRIANGLE_FLOATS: usize = 12;

/// A scene's constants for a GPU tracer, in its local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GpuSceneInfo {
    /// Local units per model unit: local = (model − `centre`) · `scale`.
    pub scale: f32,
    /// The local frame's origin in model units.
    pub centre: glam::Vec3,
    /// Hits closer than this are ignored (local units).
    pub tmin: f32,
    /// The ground: axis (0–2), height, and half size (`None`: infinite,
    /// a solid half-space).
    pub ground: Option<(u32, f32, Option<f32>)>,
    /// Deepest path from the root, in nodes (the traversal stack needs
    /// at most 7 entries per level).
    pub depth: usize,
}
