// Ray casting in compute: the estimators of core's CPU tracer
// (core/src/trace) with the same rays through the same arithmetic, so a
// ray's hit or miss is the CPU's except at float ties.
//
// A workgroup traces four points, sixteen invocations (lanes) each: lane
// l casts rays [l · group_size, min(samples, (l + 1) · group_size)), and
// the first lane adds the sixteen tallies in lane order, so the result is
// the same on every run and a point costs one tally in memory. A batch
// holds several scenes (posed meshes): their nodes and triangles are
// concatenated, and each point names its scene.
//
// * Directions: sobol_burley's Owen-scrambled Sobol sequence (dimensions
//   0 and 1; the direction numbers come from the host), mapped as core's
//   `sampling.rs` maps them, with its sine and cosine polynomial (the
//   `wide` crate's, after Agner Fog), fused where the CPU build fuses.
// * Traversal: core's 8-wide BVH (trace/bvh.rs), its child boxes exact
//   or quantised to bytes and rounded outwards (the pipeline constant
//   QUANTISED, core's NodeLayout), a stack per invocation; leaves of at
//   most three triangles, tested with obvhs's `RtTriangle::intersect`
//   (Möller–Trumbore, double-sided).
// * The ground: a solid half-space or a finite double-sided square, as
//   `LocalGround::hit`.

// What a point's rays estimate (core's trace::engine::Estimator).
const COSINE: u32 = 0u;            // any hit within tmax: count
const COSINE_EXPONENTIAL: u32 = 1u; // closest hit within tmax: Σ e^(−τt)
const VOLUME: u32 = 2u;            // closest hit: count, Σ direction, back faces
const KROON: u32 = 3u;             // closest hit: Σ facing·(1 − t/D)^α, back faces

// The largest finite f32: "no limit" (WGSL has no infinity literal).
const FAR: f32 = 3.4028235e38;
// The node layout (core's trace::engine::NodeLayout): false, the exact
// one, 16 vec4 a node; true, the quantised one, 6 vec4 a node.
override QUANTISED: bool = false;
// The count of an empty child slot (as `children` returns it).
const EMPTY: u32 = 255u;
// Traversal stack entries: 7 per level of an 8-wide tree; the host
// refuses a deeper tree.
const STACK: u32 = 96u;

struct Params {
    estimator: u32,
    samples: u32,
    // Rays per lane.
    group_size: u32,
    _pad: u32,
    // Points of this dispatch, the first one's index in the batch, and
    // workgroups per row of the dispatch grid.
    points: u32,
    first_point: u32,
    row_stride: u32,
    // Kroon: α, and 1 when the points' normals weight the hits.
    facing: u32,
    alpha: f32,
    // shared_points = 1: the points are in model units and every one is traced
    // in `scene` (a batch's scenes share them); 0: each point names its
    // scene and is in its frame.
    scene: u32,
    shared_points: u32,
    // The index of this dispatch's first tally.
    tally_base: u32,
    // Sobol direction numbers (bit-reversed) of dimensions 0 and 1, one
    // pair per index bit, most significant first: (d0, d1) of bit 2k in
    // xy and of bit 2k + 1 in zw.
    sobol: array<vec4<u32>, 8>,
}

struct SceneInfo {
    first_node: u32,
    first_triangle: u32,
    // 0: no triangles.
    nodes: u32,
    // 0–2: the ground's up axis; 3: no ground.
    ground_axis: u32,
    ground_height: f32,
    // Half edge of a finite square ground; negative: a solid half-space.
    ground_half: f32,
    // Local-frame limits: hits closer than tmin are ignored, hits beyond
    // tmax do not count; τ of the exponential falloff.
    tmin: f32,
    tmax: f32,
    tau: f32,
    // local = (model − centre) · scale.
    scale: f32,
    _pad0: u32,
    _pad1: u32,
    centre: vec3<f32>,
    _pad2: u32,
}

struct RayPoint {
    origin: vec3<f32>,
    scene: u32,
    tangent: vec3<f32>,
    seed: u32,
    bitangent: vec3<f32>,
    _pad0: u32,
    normal: vec3<f32>,
    _pad1: u32,
}

struct Tally {
    direction: vec3<f32>,
    sum: f32,
    hits: u32,
    back: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// The traversal stack: private to the invocation and zeroed once, not for
// every ray as a function's variable would be.
var<private> stack: array<u32, STACK>;
// The entry distance of each stacked node.
var<private> stack_near: array<f32, STACK>;
// A node's inner children that the ray enters, farthest first.
var<private> child_near: array<f32, 8>;
var<private> child_index: array<u32, 8>;
// Exact: 16 vec4 per node: child boxes (min x, y, z, max x, y, z of the
// eight children, two vec4 each, as f32 bits), first indices (two vec4),
// the eight counts as bytes (255: an empty slot; one vec4, xy used).
// Quantised: 6 vec4 per node: the grid's origin p (xyz, f32 bits) and
// step exponents (w, a byte per axis); first indices with the count in
// their top 3 bits (7: an empty slot; two vec4); the child boxes as bytes
// q, the plane p + q · 2^(e − 127), in the exact layout's order (three
// vec4). See Bvh8::gpu_nodes and gpu_nodes_quantised.
@group(0) @binding(1) var<storage, read> nodes: array<vec4<u32>>;
// Three vec4 per triangle: v0.xyz e1.x | e1.yz e2.xy | e2.z ng.xyz.
@group(0) @binding(2) var<storage, read> triangles: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> scenes: array<SceneInfo>;
@group(0) @binding(4) var<storage, read> points: array<RayPoint>;
@group(0) @binding(5) var<storage, read_write> tallies: array<Tally>;

// --- the direction sequence (sobol_burley 0.5) ---------------------------

fn lk_hash(x: u32) -> u32 {
    var n = x ^ 0xe6fe3bebu;
    n = n ^ (n >> 16u);
    n = n * 0x7feb352du;
    n = n ^ (n >> 15u);
    n = n * 0x846ca68bu;
    n = n ^ (n >> 16u);
    return n;
}

fn owen_scramble_rev(x: u32, scramble: u32) -> u32 {
    var n = x;
    n = n ^ (n * 0x3d20adeau);
    n = n + scramble;
    n = n * ((scramble >> 16u) | 1u);
    n = n ^ (n * 0x05526c56u);
    n = n ^ (n * 0x53a22864u);
    return n;
}

fn sobol_numbers(bit: u32) -> vec2<u32> {
    let pair = params.sobol[bit >> 1u];
    if ((bit & 1u) == 0u) {
        return pair.xy;
    }
    return pair.zw;
}

fn to_unit(rev: u32) -> f32 {
    return bitcast<f32>((reverseBits(rev) >> 9u) | 0x3f800000u) - 1.0;
}

// Sample i of the 2-D sequence scrambled by seed, in [0, 1)²
// (sobol_burley::sample_4d(i, 0, seed)'s first two dimensions).
fn sample_2d(i: u32, seed: u32) -> vec2<f32> {
    let shuffled = owen_scramble_rev(reverseBits(i), lk_hash(seed ^ 0x79c68e4au));
    var sobol = vec2<u32>(0u, 0u);
    var index = shuffled & 0xffff0000u;
    var bit = 0u;
    while (index != 0u) {
        let j = countLeadingZeros(index);
        sobol = sobol ^ sobol_numbers(bit + j);
        bit = bit + j + 1u;
        index = (index << j) << 1u;
    }
    let s = seed * 0x9c8f2d3bu;
    let u = owen_scramble_rev(sobol.x, lk_hash(s ^ 0x912f69bau));
    let v = owen_scramble_rev(sobol.y, lk_hash(s ^ 0x174f18abu));
    return vec2<f32>(to_unit(u), to_unit(v));
}

// sin and cos of x ≥ 0 as `wide`'s f32x8::sin_cos computes them on an
// AVX2 + FMA build (core's target): the same polynomials and reduction.
fn sin_cos(x: f32) -> vec2<f32> {
    let dp1 = 0.78515625 * 2.0;
    let dp2 = 2.4187564849853515625e-4 * 2.0;
    let dp3 = 3.77489497744594108e-8 * 2.0;
    let xa = abs(x);
    let y = round(xa * TWO_OVER_PI);
    let q = u32(i32(y));
    let r = fma(-y, dp3, fma(-y, dp2, fma(-y, dp1, xa)));
    let r2 = r * r;
    let r4 = r2 * r2;
    let ps = fma(r4, -1.9515295891e-4, fma(r2, 8.3321608736e-3, -1.6666654611e-1));
    let pc = fma(r4, 2.443315711809948e-5, fma(r2, -1.388731625493765e-3, 4.166664568298827e-2));
    let s = ps * (r * r2) + r;
    let c = pc * r4 + fma(-0.5, r2, 1.0);
    let swap = (q & 1u) != 0u;
    var sin1 = select(s, c, swap);
    var cos1 = select(c, s, swap);
    let sign_sin = ((q << 30u) ^ bitcast<u32>(x)) & 0x80000000u;
    sin1 = bitcast<f32>(bitcast<u32>(sin1) ^ sign_sin);
    let sign_cos = ((q + 1u) & 2u) << 30u;
    cos1 = bitcast<f32>(bitcast<u32>(cos1) ^ sign_cos);
    return vec2<f32>(sin1, cos1);
}

const TAU: f32 = 6.28318530717958647692;
// 2 / π rounded as the CPU's f32 division 2.0 / f32::consts::PI rounds.
const TWO_OVER_PI: f32 = 0.63661975;

// Cosine-weighted about the point's normal (core's cosine_hemisphere
// and cosine_directions).
fn cosine_direction(p: RayPoint, uv: vec2<f32>) -> vec3<f32> {
    let r = sqrt(uv.x);
    let sc = sin_cos(TAU * uv.y);
    let x = r * sc.y;
    let y = r * sc.x;
    let z = sqrt(max(1.0 - uv.x, 0.0));
    return p.tangent * x + p.bitangent * y + p.normal * z;
}

// Uniform on the sphere (core's uniform_sphere).
fn sphere_direction(uv: vec2<f32>) -> vec3<f32> {
    let z = 1.0 - 2.0 * uv.x;
    let r = sqrt(max(1.0 - z * z, 0.0));
    let sc = sin_cos(TAU * uv.y);
    return vec3<f32>(r * sc.y, r * sc.x, z);
}

// --- geometry ------------------------------------------------------------

struct Hit {
    t: f32,
    back_face: bool,
    found: bool,
}

fn no_hit() -> Hit {
    return Hit(FAR, false, false);
}

// glam's Vec3A::cross on an FMA build.
fn cross_fma(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(
        fma(-b.y, a.z, a.y * b.z),
        fma(-b.z, a.x, a.z * b.x),
        fma(-b.x, a.y, a.x * b.y),
    );
}

fn dot3(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return (a.x * b.x + a.y * b.y) + a.z * b.z;
}

// obvhs's RtTriangle::intersect: t within [tmin, tmax], else FAR.
fn intersect(tri: u32, origin: vec3<f32>, dir: vec3<f32>, tmin: f32, tmax: f32) -> f32 {
    let a = triangles[3u * tri];
    let b = triangles[3u * tri + 1u];
    let c4 = triangles[3u * tri + 2u];
    let v0 = a.xyz;
    let e1 = vec3<f32>(a.w, b.x, b.y);
    let e2 = vec3<f32>(b.z, b.w, c4.x);
    let ng = c4.yzw;
    let c = v0 - origin;
    let r = cross_fma(dir, c);
    let det = dot3(ng, dir);
    if (det == 0.0) {
        return FAR;
    }
    let inv_det = 1.0 / det;
    let u = dot3(r, e2) * inv_det;
    let v = dot3(r, e1) * inv_det;
    let w = (1.0 - u) - v;
    let signs = bitcast<u32>(u) | bitcast<u32>(v) | bitcast<u32>(w);
    if ((signs & 0x80000000u) != 0u) {
        return FAR;
    }
    let t = dot3(ng, c) * inv_det;
    if (t >= tmin && t <= tmax) {
        return t;
    }
    return FAR;
}

fn triangle_normal(tri: u32) -> vec3<f32> {
    return triangles[3u * tri + 2u].yzw;
}

fn safe_inverse(x: f32) -> f32 {
    let eps = 1.1920929e-7;
    if (abs(x) <= eps) {
        return select(-1.0, 1.0, (bitcast<u32>(x) & 0x80000000u) == 0u) / eps;
    }
    return 1.0 / x;
}

// vec4 per node.
fn node_size() -> u32 {
    return select(16u, 6u, QUANTISED);
}

// Children 4·half … 4·half + 3: their first node or triangle, and their
// counts (0: inner, 1–3: triangles, EMPTY: an empty slot).
struct Children {
    first: vec4<u32>,
    count: vec4<u32>,
}

fn children(base: u32, half: u32) -> Children {
    if (QUANTISED) {
        let words = nodes[base + 1u + half];
        let count = words >> vec4<u32>(29u);
        return Children(
            words & vec4<u32>(0x1fffffffu),
            select(count, vec4<u32>(EMPTY), count == vec4<u32>(7u)),
        );
    }
    let counts = nodes[base + 14u];
    let word = select(counts.x, counts.y, half == 1u);
    return Children(
        nodes[base + 12u + half],
        (vec4<u32>(word) >> vec4<u32>(0u, 8u, 16u, 24u)) & vec4<u32>(255u),
    );
}

// A quantised node's grid: its origin p and per-axis step s (a plane is
// p + q · s), decoded once per node visited; unused for exact nodes.
struct Grid {
    origin: vec3<f32>,
    step: vec3<f32>,
}

fn grid(base: u32) -> Grid {
    if (!QUANTISED) {
        return Grid(vec3<f32>(0.0), vec3<f32>(0.0));
    }
    let head = nodes[base];
    let e = (vec3<u32>(head.w) >> vec3<u32>(0u, 8u, 16u)) & vec3<u32>(255u);
    return Grid(bitcast<vec3<f32>>(head.xyz), bitcast<vec3<f32>>(e << vec3<u32>(23u)));
}

// Box planes `field` (0–2: min x, y, z; 3–5: max x, y, z) of children
// 4·half … 4·half + 3. The quantised plane is p + q · s with q · s exact,
// so it rounds once, fused or not, as the host checked it.
fn box_lanes(base: u32, g: Grid, field: u32, half: u32) -> vec4<f32> {
    if (QUANTISED) {
        let word = 2u * field + half;
        let bytes = nodes[base + 3u + word / 4u][word % 4u];
        let q = vec4<f32>((vec4<u32>(bytes) >> vec4<u32>(0u, 8u, 16u, 24u)) & vec4<u32>(255u));
        let axis = field % 3u;
        return vec4<f32>(g.origin[axis]) + q * g.step[axis];
    }
    return bitcast<vec4<f32>>(nodes[base + 2u * field + half]);
}

// The BVH of scene `s` along the ray: with `any`, whether a triangle lies
// within (tmin, tmax); otherwise the closest, with its side. Four child
// boxes are tested at once, as the CPU tests eight (the same operations in
// the same order per child), leaves as they come, and the inner children
// that the ray enters are pushed farthest first, with their entry
// distance, so the nearest is visited next and a node that starts beyond
// a closer hit is dropped when popped (any-hit rays push the children in
// slot order, without their distance: nothing is dropped before a hit
// ends them).
// Only the work depends on the order: the CPU's answer is the same (the
// closest hit is the closest in any order).
fn traverse(s: SceneInfo, origin: vec3<f32>, dir: vec3<f32>, tmax_in: f32, any: bool) -> Hit {
    var best = no_hit();
    if (s.nodes == 0u) {
        return best;
    }
    var tmax = tmax_in;
    let inv = vec3<f32>(safe_inverse(dir.x), safe_inverse(dir.y), safe_inverse(dir.z));
    let neg = inv < vec3<f32>(0.0);
    var top = 0u;
    var current = 0u;
    loop {
        let base = (s.first_node + current) * node_size();
        let g = grid(base);
        // Inner children entered, sorted by entry distance, farthest first.
        var pending = 0u;
        for (var half = 0u; half < 2u; half = half + 1u) {
            var near = vec4<f32>(s.tmin);
            var far = vec4<f32>(tmax);
            for (var a = 0u; a < 3u; a = a + 1u) {
                let lo = box_lanes(base, g, a, half);
                let hi = box_lanes(base, g, a + 3u, half);
                let n = select(lo, hi, neg[a]);
                let f = select(hi, lo, neg[a]);
                near = max(near, (n - vec4<f32>(origin[a])) * inv[a]);
                far = min(far, (f - vec4<f32>(origin[a])) * inv[a]);
            }
            let kids = children(base, half);
            for (var k = 0u; k < 4u; k = k + 1u) {
                let count = kids.count[k];
                // The second half's boxes were tested against a ray the
                // first half's leaves may have shortened: that culls only
                // children that cannot hold a closer hit.
                if (count == EMPTY || !(near[k] <= far[k])) {
                    continue;
                }
                let first = kids.first[k];
                if (count == 0u && any) {
                    // An any-hit ray takes the children in slot order and
                    // never drops one: straight onto the stack.
                    if (top < STACK) {
                        stack[top] = first;
                        top = top + 1u;
                    }
                    continue;
                }
                if (count == 0u) {
                    var j = pending;
                    // A closest-hit ray: sorted by entry distance.
                    while (j > 0u && child_near[j - 1u] < near[k]) {
                        child_near[j] = child_near[j - 1u];
                        child_index[j] = child_index[j - 1u];
                        j = j - 1u;
                    }
                    child_near[j] = near[k];
                    child_index[j] = first;
                    pending = pending + 1u;
                    continue;
                }
                for (var m = 0u; m < count; m = m + 1u) {
                    let tri = s.first_triangle + first + m;
                    let t = intersect(tri, origin, dir, s.tmin, tmax);
                    if (t < tmax) {
                        best = Hit(t, dot3(triangle_normal(tri), dir) < 0.0, true);
                        if (any) {
                            return best;
                        }
                        tmax = t;
                    }
                }
            }
        }
        for (var j = 0u; j < pending; j = j + 1u) {
            if (top < STACK) {
                stack[top] = child_index[j];
                stack_near[top] = child_near[j];
                top = top + 1u;
            }
        }
        loop {
            if (top == 0u) {
                return best;
            }
            top = top - 1u;
            if (any || stack_near[top] <= tmax) {
                current = stack[top];
                break;
            }
        }
    }
    return best;
}

// LocalGround::hit.
fn ground_hit(s: SceneInfo, origin: vec3<f32>, dir: vec3<f32>, tmax: f32) -> Hit {
    if (s.ground_axis > 2u) {
        return no_hit();
    }
    let o = origin[s.ground_axis] - s.ground_height;
    let d = dir[s.ground_axis];
    if (s.ground_half < 0.0) {
        if (o < 0.0) {
            return Hit(0.0, true, true);
        }
        if (d < 0.0) {
            let t = -o / d;
            if (t < tmax) {
                return Hit(t, false, true);
            }
        }
        return no_hit();
    }
    if (d == 0.0) {
        return no_hit();
    }
    let t = -o / d;
    if (!(t > 0.0 || (t == 0.0 && d < 0.0)) || t >= tmax) {
        return no_hit();
    }
    let a = select(0u, 1u, s.ground_axis == 0u);
    let b = select(2u, 1u, s.ground_axis == 2u);
    let pa = origin[a] + dir[a] * t;
    let pb = origin[b] + dir[b] * t;
    if (abs(pa) <= s.ground_half && abs(pb) <= s.ground_half) {
        return Hit(t, d > 0.0, true);
    }
    return no_hit();
}

fn occluded(s: SceneInfo, origin: vec3<f32>, dir: vec3<f32>, tmax: f32) -> bool {
    if (ground_hit(s, origin, dir, tmax).found) {
        return true;
    }
    return traverse(s, origin, dir, tmax, true).found;
}

fn closest(s: SceneInfo, origin: vec3<f32>, dir: vec3<f32>, tmax: f32) -> Hit {
    let ground = ground_hit(s, origin, dir, tmax);
    let limit = select(tmax, ground.t, ground.found);
    let mesh = traverse(s, origin, dir, limit, false);
    if (mesh.found) {
        return mesh;
    }
    return ground;
}

// --- the estimators --------------------------------------------------------

// Lanes per point; a workgroup traces 64 / LANES points.
const LANES: u32 = 16u;

var<workgroup> partial: array<Tally, 64>;

fn add(a: Tally, b: Tally) -> Tally {
    return Tally(a.direction + b.direction, a.sum + b.sum, a.hits + b.hits, a.back + b.back, 0u, 0u);
}

// Lane `lane`'s rays of point `p`.
fn trace_lane(p: RayPoint, lane: u32) -> Tally {
    let s = scenes[p.scene];
    var tally = Tally(vec3<f32>(0.0), 0.0, 0u, 0u, 0u, 0u);
    let cosine = params.estimator == COSINE || params.estimator == COSINE_EXPONENTIAL;
    if (cosine && all(p.normal == vec3<f32>(0.0))) {
        return tally;
    }
    let start = lane * params.group_size;
    let end = min(params.samples, start + params.group_size);
    for (var i = start; i < end; i = i + 1u) {
        let uv = sample_2d(i, p.seed);
        var dir: vec3<f32>;
        if (cosine) {
            dir = cosine_direction(p, uv);
        } else {
            dir = sphere_direction(uv);
        }
        switch params.estimator {
            case COSINE: {
                if (occluded(s, p.origin, dir, s.tmax)) {
                    tally.hits = tally.hits + 1u;
                }
            }
            case COSINE_EXPONENTIAL: {
                let hit = closest(s, p.origin, dir, s.tmax);
                if (hit.found) {
                    tally.hits = tally.hits + 1u;
                    tally.sum = tally.sum + exp(-s.tau * hit.t);
                }
            }
            case VOLUME: {
                let hit = closest(s, p.origin, dir, FAR);
                if (hit.found) {
                    tally.back = tally.back + select(0u, 1u, hit.back_face);
                    if (hit.t < s.tmax) {
                        tally.hits = tally.hits + 1u;
                        tally.direction = tally.direction + dir;
                    }
                }
            }
            default: {
                let hit = closest(s, p.origin, dir, FAR);
                if (hit.found) {
                    tally.back = tally.back + select(0u, 1u, hit.back_face);
                    if (hit.t < s.tmax) {
                        tally.hits = tally.hits + 1u;
                        var facing = 1.0;
                        if (params.facing != 0u) {
                            facing = max(dot3(p.normal, dir), 0.0);
                        }
                        let x = 1.0 - hit.t / s.tmax;
                        var falloff = 1.0;
                        if (params.alpha != 0.0) {
                            falloff = select(0.0, pow(x, params.alpha), x > 0.0);
                        }
                        tally.sum = tally.sum + facing * falloff;
                    }
                }
            }
        }
    }
    return tally;
}

@compute @workgroup_size(64)
fn cs_trace(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let slot = local / LANES;
    let lane = local % LANES;
    let n = (workgroup.y * params.row_stride + workgroup.x) * (64u / LANES) + slot;
    var tally = Tally(vec3<f32>(0.0), 0.0, 0u, 0u, 0u, 0u);
    if (n < params.points) {
        var p = points[params.first_point + n];
        if (params.shared_points != 0u) {
            // Scene::to_local's arithmetic.
            let s = scenes[params.scene];
            p.scene = params.scene;
            p.origin = (p.origin - s.centre) * s.scale;
        }
        tally = trace_lane(p, lane);
    }
    partial[local] = tally;
    workgroupBarrier();
    if (lane == 0u && n < params.points) {
        var total = partial[local];
        for (var k = 1u; k < LANES; k = k + 1u) {
            total = add(total, partial[local + k]);
        }
        tallies[params.tally_base + n] = total;
    }
}
