//! Ground-truth ambient occlusion by ray tracing (DESIGN §3–4).
//!
//! Every method in aobake is fitted to, and judged against, what this
//! module computes. Values are **occlusion**: 0 = open, 1 = blocked.
//!
//! * [`Scene`]: one BVH per posed mesh (built by obvhs, traversed as
//!   8-wide nodes with exact boxes), double-sided triangles, an optional
//!   [`Ground`].
//! * [`vertex_occlusion`], [`surface_occlusion`]: AO at the vertices of a
//!   mesh, or at any surface points, about their normals (Kontkanen & Aila
//!   Eq. 1), optionally as obscurance (Eq. 2).
//! * [`volume_occlusion`]: full-sphere occlusion at points in space and the
//!   average occluded direction (Malmer et al. Eq. 5).
//! * [`kroon_occlusion`]: Kroon's distance-weighted occlusion (Eq. 3.1).
//!
//! Directions come from [`sampling`]: an Owen-scrambled Sobol sequence
//! scrambled per point by a hash of the seed and the point's index, so a
//! result depends on the seed and the point alone, never on the thread
//! count. Points are traced in Morton order (neighbouring points share BVH
//! nodes in cache), a chunk of points per rayon task, all rays of a point
//! one after another.
//!
//! # Conventions
//!
//! * Rays of a surface point start 2e-5 of the model's diagonal off the
//!   surface along the normal; rays of a vertex also move that far into
//!   the vertex's own triangles when it lies on a boundary or crease (see
//!   [`vertex_occlusion`]). Hits closer than ~2e-6 of the diagonal along
//!   the ray are ignored. Triangles are double-sided.
//! * On closed meshes this is the textbook estimator. On open sheets it
//!   matches Blender's default bake ("shadow terminator" rule: a smooth
//!   surface counts as solid below each face's plane) on the welded-corner
//!   case, because the lifted origin sees the sheet below it; Blender with
//!   `--terminator-offset 0` differs there (0.854 against 0.707 open).
//! * Points with a zero normal (a vertex used by no triangle with area)
//!   get occlusion 0.

mod bvh;
pub mod engine;
mod error;
mod poses;
mod sampling;
mod scene;
pub mod shapes;

use glam::{Vec3, Vec3A};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use error::TraceError;
pub use poses::{AoBlock, AoRows, trace_pose, trace_posed, trace_poses};
pub use sampling::MAX_SAMPLES;
pub use scene::{Axis, BvhQuality, Ground, Scene, SceneOptions, Traversal};

use scene::Tracer;

pub use engine::{Estimator, RayBatch, RayEngine, RayPoint, Tally};
use sampling::{Frame, cosine_directions, point_seed, sphere_directions};

/// Mixed into the seed of everything held out ("heldout!" in ASCII), so
/// that the poses and rays a model is judged on are never those it was
/// fitted to.
pub const HELD_OUT_SEED: u64 = 0x6865_6c64_6f75_7421;
/// Reports progress: called with the number of points just finished, from
/// any thread.
pub type Progress<'a> = &'a (dyn Fn(usize) + Sync);

/// No progress reporting.
pub fn no_progress(_: usize) {}

/// How a hit counts in [`surface_occlusion`].
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Falloff {
    /// Ambient occlusion: a hit within the maximum distance counts 1.
    #[default]
    None,
    /// Obscurance (Kontkanen & Aila Eq. 2, after Iones et al.): the paper's
    /// openness W uses ρ(d) = 1 − e^(−τd) per direction (1 for a miss), so
    /// the occlusion 1 − W counts a hit at distance d as e^(−τd). `tau` is
    /// per model unit.
    Exponential {
        /// τ, per model unit.
        tau: f32,
    },
}

/// Parameters of [`surface_occlusion`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SurfaceParams {
    /// Rays per point, 1..=[`MAX_SAMPLES`]; powers of two stratify best.
    pub samples: u32,
    /// Hits farther than this (model units) do not occlude; may be infinite.
    pub max_distance: f32,
    /// Seed of the direction sequence.
    pub seed: u64,
    /// How a hit counts.
    pub falloff: Falloff,
}

/// Parameters of [`volume_occlusion`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VolumeParams {
    /// Rays per point, 1..=[`MAX_SAMPLES`].
    pub samples: u32,
    /// Hits farther than this (model units) do not occlude; may be infinite.
    pub max_distance: f32,
    /// Seed of the direction sequence.
    pub seed: u64,
}

/// Parameters of [`kroon_occlusion`] (Kroon 2023, Eq. 3.1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct KroonParams {
    /// Rays per point, 1..=[`MAX_SAMPLES`].
    pub samples: u32,
    /// D_max: the sampling radius (model units), finite.
    pub max_distance: f32,
    /// α: distance falloff exponent, ≥ 0.
    pub alpha: f32,
    /// w: strength, ≥ 0.
    pub weight: f32,
    /// Seed of the direction sequence.
    pub seed: u64,
}

/// Full-sphere occlusion at a point in space (Malmer et al. §4–5).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct VolumeSample {
    /// ao_grid = 2·ao′, where ao′ is the occluded fraction of the sphere
    /// (Eq. 5), so a point on an infinite plane has 1 and a point enclosed
    /// by geometry has 2. Self-occlusion uses (ao_grid − 1)/2.
    pub occlusion: f32,
    /// Unit average occluded direction (the cone axis), zero when nothing
    /// is occluded.
    pub direction: Vec3,
    /// The point is inside the mesh: more than half of its rays (traced
    /// without the distance limit) first meet the back of a triangle, as
    /// in [`kroon_occlusion`].
    pub inside: bool,
}

fn check_samples(samples: u32) -> Result<(), TraceError> {
    if samples == 0 || samples > MAX_SAMPLES {
        return Err(TraceError::Invalid(format!(
            "samples must be between 1 and {MAX_SAMPLES}, not {samples}"
        )));
    }
    Ok(())
}

fn check_distance(name: &str, d: f32, finite: bool) -> Result<(), TraceError> {
    if d.is_nan() || d <= 0.0 || (finite && d.is_infinite()) {
        let what = if finite {
            "positive and finite"
        } else {
            "positive"
        };
        return Err(TraceError::Invalid(format!(
            "{name} must be {what}, not {d}"
        )));
    }
    Ok(())
}

fn check_points(points: &[Vec3]) -> Result<(), TraceError> {
    if let Some(i) = points.iter().position(|p| !p.is_finite()) {
        return Err(TraceError::Invalid(format!("point {i} is not finite")));
    }
    if u32::try_from(points.len()).is_err() {
        return Err(TraceError::Invalid("more than 2³² points".into()));
    }
    Ok(())
}

/// Points in Morton order of their positions (ties by index), so that a
/// chunk of consecutive points is a compact region of space.
fn morton_order(points: &[Vec3]) -> Vec<u32> {
    let Some((lo, hi)) = crate::geometry::bounds(points.iter().copied()) else {
        return Vec::new();
    };
    let extent = (hi - lo).max(Vec3::splat(f32::MIN_POSITIVE));
    let mut keyed: Vec<(u64, u32)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let unit = ((*p - lo) / extent).clamp(Vec3::ZERO, Vec3::ONE);
            (
                obvhs::ploc::morton::morton_encode_u64_unorm(unit.as_dvec3()),
                i as u32,
            )
        })
        .collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// Points per rayon task: enough for the task to amortise scheduling and
/// reuse the BVH nodes of one region, few enough to balance two cores.
const CHUNK: usize = 32;

/// Traces a batch: on the process's [`RayEngine`] when one is installed
/// and takes every scene, else here, one scene after another, its points
/// in parallel and in Morton order of their origins. Tallies are returned
/// in point order.
fn trace_batch(batch: &RayBatch<'_>, progress: Progress<'_>) -> Result<Vec<Tally>, TraceError> {
    batch.check()?;
    // An engine declines a batch it cannot take (RayEngine::trace).
    if let Some(engine) = engine::engine()
        && let Some(tallies) = engine.trace(batch, progress)?
    {
        return Ok(tallies);
    }
    if batch.shared {
        let mut out = Vec::with_capacity(batch.tallies());
        for (s, scene) in batch.scenes.iter().enumerate() {
            let points: Vec<RayPoint> = batch
                .points
                .iter()
                .map(|p| RayPoint {
                    scene: s as u32,
                    origin: scene.to_local(Vec3::from(p.origin)),
                    ..*p
                })
                .collect();
            out.extend(cpu_tallies(scene, batch, &points, progress));
        }
        return Ok(out);
    }
    let mut out = Vec::with_capacity(batch.points.len());
    let mut rest = &batch.points[..];
    for (s, scene) in batch.scenes.iter().enumerate() {
        // Points come grouped by scene (checked above).
        let count = rest.iter().take_while(|p| p.scene == s as u32).count();
        let (mine, after) = rest.split_at(count);
        rest = after;
        out.extend(cpu_tallies(scene, batch, mine, progress));
    }
    Ok(out)
}

/// `points` (all in `scene`) traced here, in parallel and in Morton order
/// of their origins; tallies in point order.
fn cpu_tallies(
    scene: &Scene,
    batch: &RayBatch<'_>,
    points: &[RayPoint],
    progress: Progress<'_>,
) -> Vec<Tally> {
    let origins: Vec<Vec3> = points.iter().map(|p| Vec3::from(p.origin)).collect();
    let order = morton_order(&origins);
    let tally = CpuTally::new(scene, batch);
    let chunks: Vec<Vec<Tally>> = order
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut tracer = scene.tracer();
            let mut directions = Vec::new();
            let values = chunk
                .iter()
                .map(|&i| tally.point(&mut tracer, &mut directions, &points[i as usize]))
                .collect();
            progress(chunk.len());
            values
        })
        .collect();
    let mut out = vec![Tally::default(); points.len()];
    for (chunk, values) in order.chunks(CHUNK).zip(chunks) {
        for (&i, v) in chunk.iter().zip(values) {
            out[i as usize] = v;
        }
    }
    out
}

/// The CPU tracer's reduction of one point's rays, for one scene of a
/// batch.
struct CpuTally {
    estimator: Estimator,
    samples: u32,
    /// The maximum distance in local units.
    tmax: f32,
    /// τ in local units (the exponential falloff).
    tau: f32,
}

impl CpuTally {
    fn new(scene: &Scene, batch: &RayBatch<'_>) -> Self {
        let tau = match batch.estimator {
            Estimator::CosineExponential { tau } => tau / scene.local_distance(1.0),
            _ => 0.0,
        };
        Self {
            estimator: batch.estimator,
            samples: batch.samples,
            tmax: scene.local_distance(batch.max_distance),
            tau,
        }
    }

    fn point(&self, tracer: &mut Tracer<'_>, dirs: &mut Vec<Vec3A>, p: &RayPoint) -> Tally {
        let mut tally = Tally::default();
        let origin = p.origin;
        if self.estimator.is_cosine() {
            if p.normal == Vec3A::ZERO {
                return tally;
            }
            let frame = Frame::from_axes(p.tangent, p.bitangent, p.normal);
            cosine_directions(self.samples, p.seed, &frame, dirs);
        } else {
            sphere_directions(self.samples, p.seed, dirs);
        }
        let tmax = self.tmax;
        match self.estimator {
            Estimator::Cosine => {
                tally.hits = dirs
                    .iter()
                    .filter(|&&d| tracer.occluded(origin, d, tmax))
                    .count() as u32;
            }
            Estimator::CosineExponential { .. } => {
                for &d in dirs.iter() {
                    if let Some(h) = tracer.closest(origin, d, tmax) {
                        tally.hits += 1;
                        tally.sum += f64::from((-self.tau * h.t).exp());
                    }
                }
            }
            // The sphere estimators: closest hits without a limit, so a
            // ray also says whether it left from inside the mesh.
            Estimator::Volume | Estimator::Kroon { .. } => {
                for &d in dirs.iter() {
                    let Some(hit) = tracer.closest(origin, d, f32::INFINITY) else {
                        continue;
                    };
                    tally.back += u32::from(hit.back_face);
                    if hit.t >= tmax {
                        continue;
                    }
                    tally.hits += 1;
                    match self.estimator {
                        Estimator::Kroon { alpha, facing } => {
                            let facing = if facing {
                                p.normal.dot(d).max(0.0)
                            } else {
                                1.0
                            };
                            let falloff = (1.0 - hit.t / tmax).powf(alpha);
                            tally.sum += f64::from(facing * falloff);
                        }
                        _ => tally.direction += d,
                    }
                }
            }
        }
        tally
    }
}

/// A batch point with cosine-weighted rays about `normal` (or none, for
/// a zero normal), scrambled by point `index` of a request seeded `seed`.
fn cosine_point(scene: u32, origin: Vec3A, normal: Vec3, seed: u64, index: u32) -> RayPoint {
    let (tangent, bitangent, normal) = match normal.try_normalize() {
        Some(n) => {
            let f = Frame::new(n);
            (f.t, f.b, f.n)
        }
        None => (Vec3A::ZERO, Vec3A::ZERO, Vec3A::ZERO),
    };
    RayPoint {
        scene,
        origin,
        tangent,
        bitangent,
        normal,
        seed: point_seed(seed, index),
    }
}

/// A batch point with rays uniform on the sphere; `normal` (Kroon's facing
/// term) may be zero.
fn sphere_point(scene: u32, origin: Vec3A, normal: Vec3, seed: u64, index: u32) -> RayPoint {
    RayPoint {
        scene,
        origin,
        tangent: Vec3A::ZERO,
        bitangent: Vec3A::ZERO,
        normal: normal.normalize_or_zero().into(),
        seed: point_seed(seed, index),
    }
}

/// Surface ambient occlusion at `points` about their unit `normals`
/// (Kontkanen & Aila 2006, Eq. 1):
///
/// A(x, n) = 1/π ∫_Ω V(x, ω) (ω·n) dω,
///
/// V = 1 where geometry is hit within the maximum distance. Directions are
/// cosine-distributed about n, so the estimate is the fraction of rays that
/// hit (with [`Falloff::Exponential`], the mean of e^(−τd) over hits). Rays
/// start 2e-5 of the model's diagonal off the surface along n. Point `i` is
/// scrambled by `(seed, i)`, so its value depends on nothing else.
///
/// For the vertices of the traced mesh itself use [`vertex_occlusion`],
/// which also moves a vertex on a boundary or crease into its own faces.
pub fn surface_occlusion(
    scene: &Scene,
    points: &[Vec3],
    normals: &[Vec3],
    params: &SurfaceParams,
    progress: Progress<'_>,
) -> Result<Vec<f32>, TraceError> {
    check_surface(points, normals, params)?;
    let origins = points
        .iter()
        .zip(normals)
        .map(|(&p, &n)| scene.to_local(p) + Vec3A::from(n.normalize_or_zero()) * scene.lift())
        .collect::<Vec<_>>();
    surface_from(scene, &origins, normals, params, progress)
}

/// A triangle mesh with a unit normal per vertex: the input of
/// [`vertex_occlusion`].
#[derive(Debug, Clone, Copy)]
pub struct SurfaceMesh<'a> {
    /// Vertex positions.
    pub positions: &'a [Vec3],
    /// Unit vertex normals.
    pub normals: &'a [Vec3],
    /// Triangles, indices into `positions`.
    pub triangles: &'a [[u32; 3]],
}

/// Surface ambient occlusion at every vertex of `mesh` (usually the mesh
/// `scene` was built from), as [`surface_occlusion`], with the ray origin
/// chosen for a vertex: lifted off the surface along its normal, and, where
/// the vertex lies on a boundary or a crease (the centroid of its
/// triangles is off to one side in its tangent plane), moved the same
/// distance towards its own triangles. A floor vertex at the foot of a wall
/// then sees the wall in front of it (occlusion ½, exact) instead of lying
/// in the wall's plane; a welded 90° corner gets Blender's default value
/// (0.293: the surfaces count as solid below each face's plane).
pub fn vertex_occlusion(
    scene: &Scene,
    mesh: &SurfaceMesh<'_>,
    params: &SurfaceParams,
    progress: Progress<'_>,
) -> Result<Vec<f32>, TraceError> {
    check_surface(mesh.positions, mesh.normals, params)?;
    let origins = vertex_origins(scene, mesh)?;
    surface_from(scene, &origins, mesh.normals, params, progress)
}

/// [`vertex_occlusion`] of several posed meshes, each in its own scene,
/// traced as one batch (one dispatch on a GPU engine); each mesh's points
/// are scrambled by `(seed, vertex)` as in [`vertex_occlusion`].
pub fn vertex_occlusion_many(
    scenes: &[&Scene],
    meshes: &[SurfaceMesh<'_>],
    params: &SurfaceParams,
    progress: Progress<'_>,
) -> Result<Vec<Vec<f32>>, TraceError> {
    if scenes.len() != meshes.len() {
        return Err(TraceError::Invalid(format!(
            "{} scenes for {} meshes",
            scenes.len(),
            meshes.len()
        )));
    }
    let mut points = Vec::new();
    for (s, (scene, mesh)) in scenes.iter().zip(meshes).enumerate() {
        check_surface(mesh.positions, mesh.normals, params)?;
        let origins = vertex_origins(scene, mesh)?;
        points.extend(
            origins
                .iter()
                .zip(mesh.normals)
                .enumerate()
                .map(|(i, (&o, &n))| cosine_point(s as u32, o, n, params.seed, i as u32)),
        );
    }
    let batch = RayBatch {
        scenes: scenes.to_vec(),
        points,
        estimator: surface_estimator(params),
        samples: params.samples,
        max_distance: params.max_distance,
        shared: false,
    };
    let tallies = trace_batch(&batch, progress)?;
    let mut rest = &tallies[..];
    Ok(meshes
        .iter()
        .map(|m| {
            let (mine, after) = rest.split_at(m.positions.len());
            rest = after;
            mine.iter().map(|t| surface_value(t, params)).collect()
        })
        .collect())
}

/// The ray origins of a mesh's vertices (local frame): lifted along the
/// normal and, on a boundary or crease, slid towards the vertex's own
/// triangles (see [`vertex_occlusion`]).
fn vertex_origins(scene: &Scene, mesh: &SurfaceMesh<'_>) -> Result<Vec<Vec3A>, TraceError> {
    let n = mesh.positions.len();
    if let Some(t) = mesh
        .triangles
        .iter()
        .position(|t| t.iter().any(|&i| i as usize >= n))
    {
        return Err(TraceError::Invalid(format!(
            "triangle {t} indexes a vertex beyond the {n} given"
        )));
    }
    // Sum of (triangle centroid − vertex) over each vertex's triangles.
    let mut towards = vec![Vec3::ZERO; n];
    for t in mesh.triangles {
        let p = t.map(|i| mesh.positions[i as usize]);
        let centroid = (p[0] + p[1] + p[2]) / 3.0;
        for (k, &i) in t.iter().enumerate() {
            towards[i as usize] += centroid - p[k];
        }
    }
    let lift = scene.lift();
    let origins = (0..n)
        .map(|i| {
            let normal = mesh.normals[i].normalize_or_zero();
            let to = towards[i];
            let tangential = to - normal * to.dot(normal);
            // Only a clearly one-sided neighbourhood moves the origin: on a
            // symmetric crease the tangential part is rounding noise.
            let slide = if tangential.length() > 1e-3 * to.length() {
                tangential.normalize_or_zero()
            } else {
                Vec3::ZERO
            };
            scene.to_local(mesh.positions[i]) + Vec3A::from(normal + slide) * lift
        })
        .collect::<Vec<_>>();
    Ok(origins)
}

fn check_surface(
    points: &[Vec3],
    normals: &[Vec3],
    params: &SurfaceParams,
) -> Result<(), TraceError> {
    check_samples(params.samples)?;
    check_distance("max_distance", params.max_distance, false)?;
    check_points(points)?;
    if normals.len() != points.len() {
        return Err(TraceError::Invalid(format!(
            "{} normals for {} points",
            normals.len(),
            points.len()
        )));
    }
    if let Some(i) = normals.iter().position(|n| !n.is_finite()) {
        return Err(TraceError::Invalid(format!("normal {i} is not finite")));
    }
    if let Falloff::Exponential { tau } = params.falloff {
        check_distance("tau", tau, true)?;
    }
    Ok(())
}

/// The surface estimator from given ray origins (local frame) and their
/// normals.
fn surface_from(
    scene: &Scene,
    origins: &[Vec3A],
    normals: &[Vec3],
    params: &SurfaceParams,
    progress: Progress<'_>,
) -> Result<Vec<f32>, TraceError> {
    let batch = RayBatch {
        scenes: vec![scene],
        points: origins
            .iter()
            .zip(normals)
            .enumerate()
            .map(|(i, (&o, &n))| cosine_point(0, o, n, params.seed, i as u32))
            .collect(),
        estimator: surface_estimator(params),
        samples: params.samples,
        max_distance: params.max_distance,
        shared: false,
    };
    let tallies = trace_batch(&batch, progress)?;
    Ok(tallies.iter().map(|t| surface_value(t, params)).collect())
}

fn surface_estimator(params: &SurfaceParams) -> Estimator {
    match params.falloff {
        Falloff::None => Estimator::Cosine,
        Falloff::Exponential { tau } => Estimator::CosineExponential { tau },
    }
}

/// The surface estimator's value from a point's tally.
fn surface_value(t: &Tally, params: &SurfaceParams) -> f32 {
    match params.falloff {
        Falloff::None => t.hits as f32 / params.samples as f32,
        Falloff::Exponential { .. } => (t.sum / f64::from(params.samples)) as f32,
    }
}

/// Full-sphere volume occlusion at points in space (Malmer et al. 2005,
/// Eq. 5):
///
/// ao′(p) = 1/4π ∫_S (1 − V(ω)) dω, stored as ao_grid = 2·ao′,
///
/// where here 1 − V(ω) = 1 when geometry is hit within the maximum
/// distance (the paper's V is visibility). Directions are uniform on the
/// sphere; the average occluded direction is the normalised mean of the
/// directions that hit (§5's cone axis; its aperture follows from ao′).
/// Each ray finds its closest hit without the distance limit, so that the
/// sample also says whether the point is inside the mesh (§3.3.3's cells
/// "inside the occluder").
pub fn volume_occlusion(
    scene: &Scene,
    points: &[Vec3],
    params: &VolumeParams,
    progress: Progress<'_>,
) -> Result<Vec<VolumeSample>, TraceError> {
    let mut groups = volume_occlusion_many(scene, &[(points, params.seed)], params, progress)?;
    Ok(groups.pop().unwrap_or_default())
}

/// [`volume_occlusion`] of several groups of points in one scene, each
/// group scrambled by its own seed (`params.seed` is not used), traced as
/// one batch: one dispatch on a GPU engine. Each group's samples are those
/// [`volume_occlusion`] gives it with its seed.
pub fn volume_occlusion_many(
    scene: &Scene,
    groups: &[(&[Vec3], u64)],
    params: &VolumeParams,
    progress: Progress<'_>,
) -> Result<Vec<Vec<VolumeSample>>, TraceError> {
    check_samples(params.samples)?;
    check_distance("max_distance", params.max_distance, false)?;
    let mut points = Vec::new();
    for (group, seed) in groups {
        check_points(group)?;
        points.extend(
            group
                .iter()
                .enumerate()
                .map(|(i, &p)| sphere_point(0, scene.to_local(p), Vec3::ZERO, *seed, i as u32)),
        );
    }
    let batch = RayBatch {
        scenes: vec![scene],
        points,
        estimator: Estimator::Volume,
        samples: params.samples,
        max_distance: params.max_distance,
        shared: false,
    };
    let samples = params.samples;
    let tallies = trace_batch(&batch, progress)?;
    let mut rest = &tallies[..];
    Ok(groups
        .iter()
        .map(|(group, _)| {
            let (mine, after) = rest.split_at(group.len());
            rest = after;
            mine.iter()
                .map(|t| VolumeSample {
                    occlusion: 2.0 * t.hits as f32 / samples as f32,
                    direction: Vec3::from(t.direction.normalize_or_zero()),
                    inside: 2 * t.back > samples,
                })
                .collect()
        })
        .collect())
}

/// Kroon's occlusion at points (Kroon 2023, Eq. 3.1):
///
/// ao(P) = clamp( (w/S) Σ_{rays that hit} max(0, N·D̂) · (1 − |D|/D_max)^α, 0, 1 ),
///
/// over S directions uniform on the full sphere, D the vector from P to the
/// closest hit within D_max. Choices where the thesis is not explicit:
/// D enters the cosine term as a unit vector (the distance is in the
/// falloff term), and the sum is divided by S so that w does not depend on
/// the ray count. With `normals` = `None` (a point in space, as in the
/// cubemap method, where the receiver is not known) the N·D̂ term is 1, so
/// w = 1 gives the hit fraction weighted by the falloff. A point **inside
/// the mesh** has occlusion 1: it is inside when more than half of its rays
/// (traced without the D_max limit) first meet the back of a triangle or
/// the underside of the ground.
pub fn kroon_occlusion(
    scene: &Scene,
    points: &[Vec3],
    normals: Option<&[Vec3]>,
    params: &KroonParams,
    progress: Progress<'_>,
) -> Result<Vec<f32>, TraceError> {
    check_kroon(points, normals, params)?;
    let points = (0..points.len())
        .map(|i| {
            let n = normals.map_or(Vec3::ZERO, |n| n[i]);
            sphere_point(0, scene.to_local(points[i]), n, params.seed, i as u32)
        })
        .collect();
    kroon_batch(
        vec![scene],
        points,
        false,
        normals.is_some(),
        params,
        progress,
    )
}

/// [`kroon_occlusion`] of the same points (no normals) around several
/// scenes (posed meshes), traced as one batch: one dispatch on a GPU
/// engine. Each scene's values are those [`kroon_occlusion`] gives.
pub fn kroon_occlusion_many(
    scenes: &[&Scene],
    points: &[Vec3],
    params: &KroonParams,
    progress: Progress<'_>,
) -> Result<Vec<Vec<f32>>, TraceError> {
    check_kroon(points, None, params)?;
    if points.is_empty() {
        return Ok(vec![Vec::new(); scenes.len()]);
    }
    // The points once, in model units: each scene takes them to its frame.
    let shared = points
        .iter()
        .enumerate()
        .map(|(i, &p)| sphere_point(0, p.into(), Vec3::ZERO, params.seed, i as u32))
        .collect();
    let values = kroon_batch(scenes.to_vec(), shared, true, false, params, progress)?;
    Ok(values.chunks(points.len()).map(<[f32]>::to_vec).collect())
}

fn check_kroon(
    points: &[Vec3],
    normals: Option<&[Vec3]>,
    params: &KroonParams,
) -> Result<(), TraceError> {
    check_samples(params.samples)?;
    check_distance("max_distance", params.max_distance, true)?;
    check_points(points)?;
    if !(params.alpha.is_finite() && params.alpha >= 0.0) {
        return Err(TraceError::Invalid(format!(
            "alpha must be finite and non-negative, not {}",
            params.alpha
        )));
    }
    if !(params.weight.is_finite() && params.weight >= 0.0) {
        return Err(TraceError::Invalid(format!(
            "weight must be finite and non-negative, not {}",
            params.weight
        )));
    }
    if let Some(n) = normals
        && n.len() != points.len()
    {
        return Err(TraceError::Invalid(format!(
            "{} normals for {} points",
            n.len(),
            points.len()
        )));
    }
    Ok(())
}

/// Kroon's estimator over a batch's points.
fn kroon_batch(
    scenes: Vec<&Scene>,
    points: Vec<RayPoint>,
    shared: bool,
    facing: bool,
    params: &KroonParams,
    progress: Progress<'_>,
) -> Result<Vec<f32>, TraceError> {
    let batch = RayBatch {
        scenes,
        points,
        estimator: Estimator::Kroon {
            alpha: params.alpha,
            facing,
        },
        samples: params.samples,
        max_distance: params.max_distance,
        shared,
    };
    let samples = params.samples;
    Ok(trace_batch(&batch, progress)?
        .par_iter()
        .map(|t| {
            if 2 * t.back > samples {
                return 1.0;
            }
            ((f64::from(params.weight) * t.sum / f64::from(samples)) as f32).clamp(0.0, 1.0)
        })
        .collect())
}
