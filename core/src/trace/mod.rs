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
mod error;
mod poses;
mod sampling;
mod scene;
pub mod shapes;

use glam::{Vec3, Vec3A};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use error::TraceError;
pub use poses::{AoBlock, trace_pose, trace_poses};
pub use sampling::MAX_SAMPLES;
pub use scene::{Axis, BvhQuality, Ground, Scene, SceneOptions, Traversal};

use scene::Tracer;

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

/// Evaluates `f(tracer, directions, index)` for every point, in parallel
/// and in Morton order; results are returned in point order. `tracer` and
/// `directions` (a buffer for the point's ray directions) are reused by
/// the points of a task.
fn par_points<T: Send + Clone + Default>(
    scene: &Scene,
    points: &[Vec3],
    progress: Progress<'_>,
    f: impl Fn(&mut Tracer<'_>, &mut Vec<Vec3A>, u32) -> T + Sync,
) -> Vec<T> {
    let order = morton_order(points);
    let chunks: Vec<Vec<T>> = order
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut tracer = scene.tracer();
            let mut directions = Vec::new();
            let values = chunk
                .iter()
                .map(|&i| f(&mut tracer, &mut directions, i))
                .collect();
            progress(chunk.len());
            values
        })
        .collect();
    let mut out = vec![T::default(); points.len()];
    for (chunk, values) in order.chunks(CHUNK).zip(chunks) {
        for (&i, v) in chunk.iter().zip(values) {
            out[i as usize] = v;
        }
    }
    out
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
    Ok(surface_from(
        scene, points, &origins, normals, params, progress,
    ))
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
    Ok(surface_from(
        scene,
        mesh.positions,
        &origins,
        mesh.normals,
        params,
        progress,
    ))
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

/// The surface estimator from given ray origins (local frame); `points`
/// (world) only order the work.
fn surface_from(
    scene: &Scene,
    points: &[Vec3],
    origins: &[Vec3A],
    normals: &[Vec3],
    params: &SurfaceParams,
    progress: Progress<'_>,
) -> Vec<f32> {
    let tmax = scene.local_distance(params.max_distance);
    let samples = params.samples;
    par_points(scene, points, progress, |tracer, dirs, i| {
        let Some(n) = normals[i as usize].try_normalize() else {
            return 0.0;
        };
        let origin = origins[i as usize];
        let frame = Frame::new(n);
        let seed = point_seed(params.seed, i);
        cosine_directions(samples, seed, &frame, dirs);
        let dirs = dirs.iter().copied();
        match params.falloff {
            Falloff::None => {
                let hits = dirs.filter(|&d| tracer.occluded(origin, d, tmax)).count();
                hits as f32 / samples as f32
            }
            Falloff::Exponential { tau } => {
                let tau_local = tau / scene.local_distance(1.0);
                let sum: f64 = dirs
                    .filter_map(|d| tracer.closest(origin, d, tmax))
                    .map(|h| f64::from((-tau_local * h.t).exp()))
                    .sum();
                (sum / f64::from(samples)) as f32
            }
        }
    })
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
    check_samples(params.samples)?;
    check_distance("max_distance", params.max_distance, false)?;
    check_points(points)?;
    let tmax = scene.local_distance(params.max_distance);
    let samples = params.samples;
    Ok(par_points(scene, points, progress, |tracer, dirs, i| {
        let origin = scene.to_local(points[i as usize]);
        let seed = point_seed(params.seed, i);
        let (mut hits, mut back) = (0u32, 0u32);
        let mut sum = Vec3A::ZERO;
        sphere_directions(samples, seed, dirs);
        for &d in dirs.iter() {
            let Some(hit) = tracer.closest(origin, d, f32::INFINITY) else {
                continue;
            };
            back += u32::from(hit.back_face);
            if hit.t < tmax {
                hits += 1;
                sum += d;
            }
        }
        VolumeSample {
            occlusion: 2.0 * hits as f32 / samples as f32,
            direction: Vec3::from(sum.normalize_or_zero()),
            inside: 2 * back > samples,
        }
    }))
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
    let d_max = scene.local_distance(params.max_distance);
    let samples = params.samples;
    Ok(par_points(scene, points, progress, |tracer, dirs, i| {
        let origin = scene.to_local(points[i as usize]);
        let normal = normals.map(|n| Vec3A::from(n[i as usize].normalize_or_zero()));
        let seed = point_seed(params.seed, i);
        let mut back = 0u32;
        let mut sum = 0.0f64;
        sphere_directions(samples, seed, dirs);
        for &d in dirs.iter() {
            let Some(hit) = tracer.closest(origin, d, f32::INFINITY) else {
                continue;
            };
            back += u32::from(hit.back_face);
            if hit.t < d_max {
                let facing = normal.map_or(1.0, |n| n.dot(d).max(0.0));
                let falloff = (1.0 - hit.t / d_max).powf(params.alpha);
                sum += f64::from(facing * falloff);
            }
        }
        if 2 * back > samples {
            return 1.0;
        }
        ((f64::from(params.weight) * sum / f64::from(samples)) as f32).clamp(0.0, 1.0)
    }))
}
