//! The occluder: one BVH over a posed mesh, an optional ground, and the two
//! ray queries the estimators need (any hit within a distance, and closest
//! hit with the side of the surface that was hit).

use glam::{Vec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    bvh2::{Bvh2, builder::build_bvh2},
    cwbvh::{CwBvh, builder::build_cwbvh},
    ray::{Ray, RayHit},
    rt_triangle::RtTriangle,
};
use serde::{Deserialize, Serialize};

use super::{
    bvh::Bvh8,
    engine::{GPU_TRIANGLE_FLOATS, GpuSceneInfo, NodeLayout},
    error::TraceError,
};

/// The scene is traced in a local frame: centred on the mesh's bounding
/// box and scaled by a power of two (exact in floating point) so that the
/// diagonal is between 45 and 91 units. obvhs culls BVH nodes that end
/// closer than an absolute 1e-4 along the ray; in this frame that is about
/// 2e-6 of the model, whatever units the model came in.
const LOCAL_DIAGONAL: f32 = 64.0;

/// Surface rays start this fraction of the model's bounding-box diagonal
/// off the surface (the self-intersection offset). Rounding of positions
/// is ~1e-7 of the coordinates, far below; the model's own detail is far
/// above (2e-5 of a 1.8 m character is 36 µm).
const LIFT: f32 = 2e-5;

/// Hits closer than this along a ray (local units) are ignored; it is just
/// above the distance under which obvhs culls BVH nodes (1e-4), so a
/// triangle is never hit closer than its node can be.
const TMIN: f32 = 2e-4;

/// A coordinate axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// x
    X,
    /// y (glTF's up axis)
    Y,
    /// z (Blender's up axis)
    Z,
}

impl Axis {
    fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }
}

/// A ground plane perpendicular to `up` at coordinate `height`.
///
/// Without `half_size` the ground is a solid half-space: everything below
/// `height` is inside it, so a point resting on it (a foot sole) is
/// occluded by it. With `half_size` it is a double-sided square of that
/// half edge centred under the mesh's bounding box, as Blender's reference
/// baker builds it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Ground {
    /// The up axis.
    pub up: Axis,
    /// Coordinate of the plane along `up`, in model units.
    pub height: f32,
    /// Half edge of a finite square ground; `None` for an infinite one.
    pub half_size: Option<f32>,
}

/// BVH build quality: a trade of build time against trace speed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BvhQuality {
    /// obvhs `fast_build`.
    Fast,
    /// obvhs `medium_build`.
    #[default]
    Medium,
    /// obvhs `slow_build` (spatial pre-splits are not used: primitives are
    /// given as boxes).
    Slow,
}

impl BvhQuality {
    fn params(self) -> BvhBuildParams {
        match self {
            BvhQuality::Fast => BvhBuildParams::fast_build(),
            BvhQuality::Medium => BvhBuildParams::medium_build(),
            BvhQuality::Slow => BvhBuildParams::slow_build(),
        }
    }
}

/// Which traversal kernel answers ray queries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Traversal {
    /// aobake's 8-wide BVH with exact f32 child boxes (see `bvh.rs`),
    /// converted from obvhs's tree: the fastest.
    #[default]
    Wide,
    /// obvhs's own CWBVH traversal (`ray_traverse_miss`), kept to compare.
    Obvhs,
    /// obvhs's binary BVH (BVH2) and its traversal, kept to compare.
    ObvhsBvh2,
}

/// How to build a [`Scene`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SceneOptions {
    /// Optional ground plane.
    pub ground: Option<Ground>,
    /// BVH build quality.
    pub quality: BvhQuality,
    /// Traversal kernel.
    pub traversal: Traversal,
}

/// The acceleration structure over the triangles.
enum Accel {
    /// No triangle with area.
    Empty,
    Obvhs(CwBvh),
    Bvh2(Bvh2),
    Wide(Bvh8),
}

/// The closest surface along a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Hit {
    /// Distance in local units.
    pub t: f32,
    /// The ray hit the back of a triangle (its counter-clockwise normal
    /// points along the ray) or entered the ground from below.
    pub back_face: bool,
}

/// The ground in the local frame.
#[derive(Debug, Clone, Copy)]
struct LocalGround {
    axis: usize,
    height: f32,
    /// Half edge of a finite square, centred under the mesh's bounding box
    /// (the local origin).
    half_size: Option<f32>,
}

impl LocalGround {
    fn others(&self) -> [usize; 2] {
        match self.axis {
            0 => [1, 2],
            1 => [0, 2],
            _ => [0, 1],
        }
    }

    /// Distance to the ground along the ray, if it is hit before `tmax`;
    /// `Some(0)` and `back_face` for an origin inside the solid half-space.
    fn hit(&self, origin: Vec3A, dir: Vec3A, tmax: f32) -> Option<Hit> {
        let o = origin[self.axis] - self.height;
        let d = dir[self.axis];
        match self.half_size {
            None => {
                if o < 0.0 {
                    return Some(Hit {
                        t: 0.0,
                        back_face: true,
                    });
                }
                // Going down from on or above the plane.
                if d < 0.0 {
                    let t = -o / d;
                    if t < tmax {
                        return Some(Hit {
                            t,
                            back_face: false,
                        });
                    }
                }
                None
            }
            Some(half) => {
                if d == 0.0 {
                    return None;
                }
                let t = -o / d;
                // A point on the plane is occluded by it only going down.
                if !(t > 0.0 || (t == 0.0 && d < 0.0)) || t >= tmax {
                    return None;
                }
                let [a, b] = self.others();
                let pa = origin[a] + dir[a] * t;
                let pb = origin[b] + dir[b] * t;
                (pa.abs() <= half && pb.abs() <= half).then_some(Hit {
                    t,
                    back_face: d > 0.0,
                })
            }
        }
    }
}

/// A posed mesh (and optional ground) ready for ray queries.
///
/// Triangles are double-sided. Degenerate triangles (zero area) are
/// dropped; they cannot be hit.
pub struct Scene {
    accel: Accel,
    /// Triangles in BVH primitive order, in the local frame.
    triangles: Vec<RtTriangle>,
    /// The index in the caller's triangle list of each of `triangles`.
    ids: Vec<u32>,
    centre: Vec3A,
    /// local = (world − centre) · scale.
    scale: f32,
    /// Self-intersection offset of surface points, in local units.
    lift: f32,
    ground: Option<LocalGround>,
    /// World-space bounding box of the mesh.
    bounds: (Vec3, Vec3),
}

impl std::fmt::Debug for Scene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Scene")
            .field("triangles", &self.triangles.len())
            .field("nodes", &self.node_count())
            .field("bounds", &self.bounds)
            .field("ground", &self.ground)
            .finish_non_exhaustive()
    }
}

impl Scene {
    /// Builds the BVH over `triangles` (indices into `positions`).
    pub fn new(
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        options: &SceneOptions,
    ) -> Result<Scene, TraceError> {
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(TraceError::Invalid(format!(
                "vertex {i} has a non-finite position"
            )));
        }
        let n = positions.len();
        if let Some((t, _)) = triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&i| i as usize >= n))
        {
            return Err(TraceError::Invalid(format!(
                "triangle {t} indexes a vertex beyond the {n} given"
            )));
        }
        let (lo, hi) =
            crate::geometry::bounds(positions.iter().copied()).unwrap_or((Vec3::ZERO, Vec3::ZERO));
        let diagonal = (hi - lo).length();
        let scale = if diagonal > 0.0 && diagonal.is_finite() {
            (LOCAL_DIAGONAL / diagonal).log2().round().exp2()
        } else {
            1.0
        };
        let centre = Vec3A::from((lo + hi) * 0.5);
        let local = |p: Vec3| (Vec3A::from(p) - centre) * scale;

        let (mut tris, mut ids): (Vec<RtTriangle>, Vec<u32>) = triangles
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let tri = RtTriangle::new(
                    local(positions[t[0] as usize]),
                    local(positions[t[1] as usize]),
                    local(positions[t[2] as usize]),
                );
                (tri, i as u32)
            })
            .filter(|(t, _)| t.ng.length_squared() > 0.0 && t.ng.is_finite())
            .unzip();
        let params = options.quality.params();
        let accel = if tris.is_empty() {
            Accel::Empty
        } else if options.traversal == Traversal::ObvhsBvh2 {
            let bvh = build_bvh2(&tris, params, &mut std::time::Duration::default());
            tris = in_order(&tris, &bvh.primitive_indices);
            ids = in_order(&ids, &bvh.primitive_indices);
            Accel::Bvh2(bvh)
        } else {
            let bvh = build_cwbvh(&tris, params, &mut std::time::Duration::default());
            tris = in_order(&tris, &bvh.primitive_indices);
            ids = in_order(&ids, &bvh.primitive_indices);
            if options.traversal == Traversal::Wide {
                Accel::Wide(Bvh8::new(&bvh, &tris))
            } else {
                Accel::Obvhs(bvh)
            }
        };

        let ground = match options.ground {
            None => None,
            Some(g) => {
                if !g.height.is_finite() || g.half_size.is_some_and(|h| !(h.is_finite() && h > 0.0))
                {
                    return Err(TraceError::Invalid(
                        "the ground's height and half size must be finite, and the half size positive".into(),
                    ));
                }
                let axis = g.up.index();
                Some(LocalGround {
                    axis,
                    height: (g.height - centre[axis]) * scale,
                    half_size: g.half_size.map(|half| half * scale),
                })
            }
        };
        let local_diagonal = diagonal * scale;
        Ok(Scene {
            accel,
            triangles: tris,
            ids,
            centre,
            scale,
            lift: (LIFT * local_diagonal).max(4.0 * TMIN),
            ground,
            bounds: (lo, hi),
        })
    }

    /// World-space bounding box of the mesh (ground excluded).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.bounds
    }

    /// Number of triangles in the BVH (degenerate ones dropped).
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Number of BVH nodes.
    pub fn node_count(&self) -> usize {
        match &self.accel {
            Accel::Empty => 0,
            Accel::Obvhs(bvh) => bvh.nodes.len(),
            Accel::Bvh2(bvh) => bvh.nodes.len(),
            Accel::Wide(bvh) => bvh.node_count(),
        }
    }

    /// The scene's constants for a GPU tracer, or `None` when its tree is
    /// not aobake's wide BVH (the comparison kernels are CPU-only).
    pub fn gpu_info(&self) -> Option<GpuSceneInfo> {
        let depth = match &self.accel {
            Accel::Empty => 0,
            Accel::Wide(bvh) => bvh.depth(),
            Accel::Obvhs(_) | Accel::Bvh2(_) => return None,
        };
        Some(GpuSceneInfo {
            scale: self.scale,
            centre: self.centre.into(),
            tmin: TMIN,
            ground: self.ground.map(|g| (g.axis as u32, g.height, g.half_size)),
            depth,
        })
    }

    /// The wide BVH's nodes for a GPU tracer, `layout.words()` words
    /// each (see `bvh.rs`), empty without triangles or with another tree.
    pub fn gpu_nodes(&self, layout: NodeLayout) -> Vec<u32> {
        match (&self.accel, layout) {
            (Accel::Wide(bvh), NodeLayout::Exact) => bvh.gpu_nodes(),
            (Accel::Wide(bvh), NodeLayout::Quantised) => bvh.gpu_nodes_quantised(),
            _ => Vec::new(),
        }
    }

    /// The triangles in the BVH's leaf order for a GPU tracer,
    /// [`GPU_TRIANGLE_FLOATS`] floats each: v0, e1 = v0 − v1, e2 = v2 − v0
    /// and ng = e1 × e2 (obvhs's `RtTriangle`, local frame).
    pub fn gpu_triangles(&self) -> Vec<f32> {
        let mut out = Vec::with_capacity(self.triangles.len() * GPU_TRIANGLE_FLOATS);
        for t in &self.triangles {
            for v in [t.v0, t.e1, t.e2, t.ng] {
                out.extend(v.to_array());
            }
        }
        out
    }

    /// World point to the local frame: (p − centre) · scale.
    pub fn to_local(&self, p: Vec3) -> Vec3A {
        (Vec3A::from(p) - self.centre) * self.scale
    }

    /// How far surface rays start off the surface, in local units.
    pub(crate) fn lift(&self) -> f32 {
        self.lift
    }

    /// World distance to local; infinity stays infinite.
    pub(crate) fn local_distance(&self, d: f32) -> f32 {
        d * self.scale
    }

    /// Whether a surface crosses the segment from `p − reach·dir` to
    /// `p + reach·dir` (world units; `dir` need not be unit length): a
    /// point lying on a surface counts, which a ray starting there would
    /// miss.
    pub fn surface_near(&self, p: Vec3, dir: Vec3, reach: f32) -> bool {
        let d = dir.normalize_or_zero();
        if d == Vec3::ZERO || !p.is_finite() || reach.is_nan() || reach <= 0.0 {
            return false;
        }
        self.tracer().occluded(
            self.to_local(p - reach * d),
            Vec3A::from(d),
            self.local_distance(2.0 * reach),
        )
    }

    /// The first triangle of the mesh (ground excluded) along the ray from
    /// `origin` in direction `dir` (world units, `dir` need not be unit
    /// length): its index in the triangle list the scene was built from,
    /// and the world distance along the unit direction. What a camera ray
    /// through a pixel sees.
    pub fn first_hit(&self, origin: Vec3, dir: Vec3) -> Option<(usize, f32)> {
        let d = dir.normalize_or_zero();
        if d == Vec3::ZERO || !origin.is_finite() {
            return None;
        }
        let ray = Ray::new(self.to_local(origin), Vec3A::from(d), TMIN, f32::INFINITY);
        let hit = self.nearest_triangle(ray, &mut Vec::with_capacity(64));
        hit.map(|(i, t)| (self.ids[i] as usize, t / self.scale))
    }

    /// The nearest triangle along `ray` (local frame; the ground left
    /// out): its index in BVH order and the distance.
    #[inline]
    fn nearest_triangle(&self, ray: Ray, stack: &mut Vec<u32>) -> Option<(usize, f32)> {
        match &self.accel {
            Accel::Empty => None,
            Accel::Wide(bvh) => bvh.traverse::<false>(&self.triangles, ray, stack),
            Accel::Obvhs(bvh) => {
                let mut hit = RayHit::none();
                bvh.ray_traverse(ray, &mut hit, |ray, id| self.triangles[id].intersect(ray))
                    .then_some((hit.primitive_id as usize, hit.t))
            }
            Accel::Bvh2(bvh) => {
                let mut hit = RayHit::none();
                bvh.ray_traverse(ray, &mut hit, |ray, id| self.triangles[id].intersect(ray))
                    .then_some((hit.primitive_id as usize, hit.t))
            }
        }
    }

    /// A ray-query context for one thread (it owns the traversal stack).
    pub(crate) fn tracer(&self) -> Tracer<'_> {
        Tracer {
            scene: self,
            stack: Vec::with_capacity(64),
        }
    }
}

/// `items` (one per triangle) in a BVH's primitive order, so that its
/// leaves index them directly.
fn in_order<T: Copy>(items: &[T], primitive_indices: &[u32]) -> Vec<T> {
    primitive_indices
        .iter()
        .map(|&i| items[i as usize])
        .collect()
}

/// Ray queries against a [`Scene`], with scratch space reused between
/// rays; one per thread or task.
pub(crate) struct Tracer<'a> {
    scene: &'a Scene,
    stack: Vec<u32>,
}

impl Tracer<'_> {
    /// True when a surface lies along the ray within (TMIN, `tmax`) (local
    /// units). Stops at the first hit.
    #[inline]
    pub(crate) fn occluded(&mut self, origin: Vec3A, dir: Vec3A, tmax: f32) -> bool {
        let scene = self.scene;
        if let Some(g) = &scene.ground
            && g.hit(origin, dir, tmax).is_some()
        {
            return true;
        }
        let ray = Ray::new(origin, dir, TMIN, tmax);
        match &scene.accel {
            Accel::Empty => false,
            Accel::Wide(bvh) => bvh
                .traverse::<true>(&scene.triangles, ray, &mut self.stack)
                .is_some(),
            Accel::Obvhs(bvh) => {
                !bvh.ray_traverse_miss(ray, |ray, id| scene.triangles[id].intersect(ray))
            }
            Accel::Bvh2(bvh) => {
                !bvh.ray_traverse_miss(ray, |ray, id| scene.triangles[id].intersect(ray))
            }
        }
    }

    /// The closest surface along the ray within (TMIN, `tmax`) (local units).
    pub(crate) fn closest(&mut self, origin: Vec3A, dir: Vec3A, tmax: f32) -> Option<Hit> {
        let scene = self.scene;
        let ground = scene.ground.as_ref().and_then(|g| g.hit(origin, dir, tmax));
        let tmax = ground.map_or(tmax, |g| g.t);
        let ray = Ray::new(origin, dir, TMIN, tmax);
        let mesh = scene.nearest_triangle(ray, &mut self.stack);
        mesh.map(|(id, t)| Hit {
            t,
            // RtTriangle stores ng = (v0 − v1) × (v2 − v0), the opposite of
            // the counter-clockwise normal.
            back_face: scene.triangles[id].ng.dot(dir) < 0.0,
        })
        .or(ground)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_hit_names_the_callers_triangle_on_every_traversal() {
        // A degenerate triangle first (dropped from the BVH), then three
        // unit squares' halves stacked along z at 0, 1 and 2.
        let mut positions = vec![Vec3::ZERO, Vec3::ZERO, Vec3::ZERO];
        let mut triangles = vec![[0, 1, 2]];
        for z in [2.0, 0.0, 1.0] {
            let base = positions.len() as u32;
            positions.extend([
                Vec3::new(0.0, 0.0, z),
                Vec3::new(1.0, 0.0, z),
                Vec3::new(0.0, 1.0, z),
            ]);
            triangles.push([base, base + 1, base + 2]);
        }
        for traversal in [Traversal::Wide, Traversal::Obvhs, Traversal::ObvhsBvh2] {
            let options = SceneOptions {
                traversal,
                ..SceneOptions::default()
            };
            let scene = Scene::new(&positions, &triangles, &options).unwrap();
            let eye = Vec3::new(0.25, 0.25, -3.0);
            let (t, d) = scene.first_hit(eye, Vec3::Z * 5.0).unwrap();
            assert_eq!(t, 2, "{traversal:?}: the square at z = 0");
            assert!((d - 3.0).abs() < 1e-4, "{traversal:?}: {d}");
            let (t, _) = scene
                .first_hit(Vec3::new(0.25, 0.25, 1.5), Vec3::Z)
                .unwrap();
            assert_eq!(t, 1, "{traversal:?}: the square at z = 2");
            assert_eq!(scene.first_hit(eye, -Vec3::Z), None);
            assert_eq!(scene.first_hit(eye, Vec3::ZERO), None);
        }
    }
}
