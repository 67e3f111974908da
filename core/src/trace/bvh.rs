//! An 8-wide BVH with full-precision child boxes, traversed one ray at a
//! time with the eight child slab tests in one SIMD step.
//!
//! obvhs builds the tree (PLOC, reinsertion, collapse to 8 children, at
//! most 3 triangles per leaf); its compressed node stores child boxes as
//! bytes, and decoding them on every visit is most of obvhs's node test.
//! Rays of a vertex all start at one point and go everywhere, so the same
//! nodes near the origin are visited hundreds of times: here the boxes are
//! decoded once, tightened to the exact bounds of their triangles, and
//! stored as eight-lane vectors (`wide::f32x8`). Measured on the 101k
//! triangle benchmark mesh, this traverses about 1.5× faster than obvhs's
//! own `ray_traverse_miss` on the same tree (`aobake bench trace`).

use glam::Vec3A;
use obvhs::{cwbvh::CwBvh, ray::Ray, rt_triangle::RtTriangle};
use rayon::prelude::*;
use wide::f32x8;

use super::engine::{GPU_NODE_WORDS, GPU_QUANTISED_NODE_WORDS};

/// Child slot of an internal node: the child's box and what it is.
#[derive(Clone, Copy)]
struct Node {
    /// Box minimum per axis, one lane per child. Empty slots hold +∞ in
    /// `lo` and −∞ in `hi`, which no ray hits.
    lo: [f32x8; 3],
    hi: [f32x8; 3],
    /// Node index (`count` 0) or first triangle (`count` 1..=3).
    first: [u32; 8],
    count: [u8; 8],
}

/// The tree; leaves index the triangles it was built over, in obvhs's
/// primitive order.
pub(crate) struct Bvh8 {
    nodes: Vec<Node>,
}

impl Node {
    /// Whether child slot `c` is empty (its box inverted).
    fn is_empty(&self, c: usize) -> bool {
        self.lo[0].to_array()[c] > self.hi[0].to_array()[c]
    }
}

fn union(a: (Vec3A, Vec3A), b: (Vec3A, Vec3A)) -> (Vec3A, Vec3A) {
    (a.0.min(b.0), a.1.max(b.1))
}

const EMPTY: (Vec3A, Vec3A) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);

/// Empty child slots: +∞ in `lo` and −∞ in `hi`.
const EMPTY_NODE: Node = Node {
    lo: [f32x8::splat(f32::INFINITY); 3],
    hi: [f32x8::splat(f32::NEG_INFINITY); 3],
    first: [0; 8],
    count: [0; 8],
};

impl Bvh8 {
    /// Converts obvhs's tree; `triangles[i]` is primitive `i` of `cw`
    /// (i.e. already in `cw.primitive_indices` order).
    pub(crate) fn new(cw: &CwBvh, triangles: &[RtTriangle]) -> Bvh8 {
        // Parents before children (obvhs does not promise an index order),
        // then converted in reverse, so children's bounds are known first.
        let mut order = Vec::with_capacity(cw.nodes.len());
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            order.push(i);
            let node = &cw.nodes[i];
            stack.extend(
                (0..8)
                    .filter(|&c| !node.is_child_empty(c) && !node.is_leaf(c))
                    .map(|c| node.child_node_index(c) as usize),
            );
        }
        let mut nodes = vec![EMPTY_NODE; cw.nodes.len()];
        let mut bounds = vec![EMPTY; cw.nodes.len()];
        for &i in order.iter().rev() {
            (nodes[i], bounds[i]) = convert(cw, triangles, &bounds, i);
        }
        Bvh8 { nodes }
    }

    pub(crate) fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The nodes for a GPU tracer, [`GPU_NODE_WORDS`] words each: the
    /// child boxes as f32 bits (min x of the eight children, then min y,
    /// min z, max x, max y, max z), the eight `first` indices, the eight
    /// counts as bytes (255: an empty slot), then padding.
    pub(crate) fn gpu_nodes(&self) -> Vec<u32> {
        let mut out = Vec::with_capacity(self.nodes.len() * GPU_NODE_WORDS);
        for node in &self.nodes {
            let start = out.len();
            for lanes in node.lo.iter().chain(&node.hi) {
                out.extend(lanes.to_array().map(f32::to_bits));
            }
            out.extend(node.first);
            let counts = std::array::from_fn::<u8, 8, _>(|c| {
                if node.is_empty(c) {
                    u8::MAX
                } else {
                    node.count[c]
                }
            });
            out.push(u32::from_le_bytes([
                counts[0], counts[1], counts[2], counts[3],
            ]));
            out.push(u32::from_le_bytes([
                counts[4], counts[5], counts[6], counts[7],
            ]));
            out.resize(start + GPU_NODE_WORDS, 0);
        }
        out
    }

    /// The nodes for a GPU tracer in
    /// [`NodeLayout::Quantised`](super::engine::NodeLayout::Quantised),
    /// [`GPU_QUANTISED_NODE_WORDS`] words each:
    ///
    /// * words 0–2: `p`, the grid's origin (the children's lowest corner),
    ///   as f32 bits; word 3: the grid step of each axis as an f32
    ///   exponent byte (`s = 2^(e − 127)`, x in the low byte);
    /// * words 4–11: child `c`'s first node or triangle, with its count in
    ///   the top 3 bits (0: an inner node, 1–3: a leaf's triangles, 7: an
    ///   empty slot);
    /// * words 12–23: the child boxes as bytes `q`, the plane being
    ///   `p + q · s`: min x of children 0–3, then of 4–7, min y, min z,
    ///   max x, max y, max z the same way.
    ///
    /// The bytes are rounded outwards and checked in the arithmetic the
    /// shader uses (`q · s` is exact, so one rounding whether fused or
    /// not), so each decoded box contains its exact box: a ray's slab test
    /// (monotonic in the planes) enters every child it enters with exact
    /// boxes. A GPU may flush subnormal floats to zero: coordinates in
    /// the subnormal band are first moved outwards out of it (to 0 or
    /// ±2⁻¹²⁶), so every plane decoded near zero is a multiple of 2⁻¹²⁶
    /// or lies on the safe side of zero, and containment holds flushed or
    /// not.
    pub(crate) fn gpu_nodes_quantised(&self) -> Vec<u32> {
        let nodes: Vec<[u32; GPU_QUANTISED_NODE_WORDS]> =
            self.nodes.par_iter().map(quantised_node).collect();
        nodes.into_iter().flatten().collect()
    }

    /// Nodes on the longest path from the root.
    pub(crate) fn depth(&self) -> usize {
        let mut deepest = 1;
        let mut stack = vec![(0usize, 1usize)];
        while let Some((i, depth)) = stack.pop() {
            deepest = deepest.max(depth);
            let node = &self.nodes[i];
            for c in 0..8 {
                if node.count[c] == 0 && !node.is_empty(c) {
                    stack.push((node.first[c] as usize, depth + 1));
                }
            }
        }
        deepest
    }

    /// Traverses the tree for `ray` over `triangles` (those it was built
    /// from). With `ANY` it stops at the first triangle hit within
    /// (tmin, tmax); otherwise it finds the closest. The result is
    /// (triangle index, t). `stack` is scratch space, reused between rays.
    #[inline]
    pub(crate) fn traverse<const ANY: bool>(
        &self,
        triangles: &[RtTriangle],
        mut ray: Ray,
        stack: &mut Vec<u32>,
    ) -> Option<(usize, f32)> {
        let inv = ray.inv_direction;
        let o = ray.origin;
        let neg = [inv.x < 0.0, inv.y < 0.0, inv.z < 0.0];
        let inv8 = [
            f32x8::splat(inv.x),
            f32x8::splat(inv.y),
            f32x8::splat(inv.z),
        ];
        let o8 = [f32x8::splat(o.x), f32x8::splat(o.y), f32x8::splat(o.z)];
        let tmin8 = f32x8::splat(ray.tmin);
        let mut best = None;

        stack.clear();
        let mut current = 0u32;
        loop {
            let node = &self.nodes[current as usize];
            let mut near = tmin8;
            let mut far = f32x8::splat(ray.tmax);
            for a in 0..3 {
                let (n, f) = if neg[a] {
                    (node.hi[a], node.lo[a])
                } else {
                    (node.lo[a], node.hi[a])
                };
                near = near.fast_max((n - o8[a]) * inv8[a]);
                far = far.fast_min((f - o8[a]) * inv8[a]);
            }
            let mut mask = near.simd_le(far).to_bitmask();
            while mask != 0 {
                let c = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let first = node.first[c];
                match node.count[c] {
                    0 => stack.push(first),
                    n => {
                        let first = first as usize;
                        for (k, tri) in triangles[first..first + usize::from(n)].iter().enumerate()
                        {
                            let t = tri.intersect(&ray);
                            if t < ray.tmax {
                                if ANY {
                                    return Some((first + k, t));
                                }
                                ray.tmax = t;
                                best = Some((first + k, t));
                            }
                        }
                    }
                }
            }
            match stack.pop() {
                Some(next) => current = next,
                None => return best,
            }
        }
    }
}

/// One node in [`Bvh8::gpu_nodes_quantised`]'s layout.
fn quantised_node(node: &Node) -> [u32; GPU_QUANTISED_NODE_WORDS] {
    let lo: [[f32; 8]; 3] = node.lo.map(|l| l.to_array().map(below_subnormals));
    let hi: [[f32; 8]; 3] = node.hi.map(|h| h.to_array().map(|x| -below_subnormals(-x)));
    let used = |c: &usize| !node.is_empty(*c);
    let mut out = [0u32; GPU_QUANTISED_NODE_WORDS];
    let mut planes = [[0u8; 8]; 6];
    for a in 0..3 {
        let p = (0..8)
            .filter(used)
            .map(|c| lo[a][c])
            .fold(f32::INFINITY, f32::min);
        let top = (0..8)
            .filter(used)
            .map(|c| hi[a][c])
            .fold(f32::NEG_INFINITY, f32::max);
        let (p, e) = if p <= top {
            (p, grid_exponent(p, top))
        } else {
            // No child: any grid.
            (0.0, 127)
        };
        let s = step(e);
        out[a] = p.to_bits();
        out[3] |= e << (8 * a);
        for c in (0..8).filter(used) {
            planes[a][c] = quantise_down(p, s, lo[a][c]);
            planes[a + 3][c] = quantise_up(p, s, hi[a][c]);
        }
    }
    for c in 0..8 {
        let count = if node.is_empty(c) {
            QUANTISED_EMPTY
        } else {
            u32::from(node.count[c])
        };
        debug_assert!(node.first[c] < 1 << 29);
        out[4 + c] = node.first[c] | count << 29;
    }
    for (f, field) in planes.iter().enumerate() {
        for (h, half) in field.chunks_exact(4).enumerate() {
            out[12 + 2 * f + h] = u32::from_le_bytes([half[0], half[1], half[2], half[3]]);
        }
    }
    out
}

/// The count of an empty child slot in [`Bvh8::gpu_nodes_quantised`].
const QUANTISED_EMPTY: u32 = 7;

/// `x`, or where it is subnormal the next value at or below it that is
/// not (0 or −2⁻¹²⁶): a plane no GPU's flushing can move.
fn below_subnormals(x: f32) -> f32 {
    if x.is_subnormal() {
        if x > 0.0 { 0.0 } else { -f32::MIN_POSITIVE }
    } else {
        x
    }
}

/// The grid step `2^(e − 127)` of exponent byte `e` (1..=254).
fn step(e: u32) -> f32 {
    f32::from_bits(e << 23)
}

/// A plane of the quantised grid as the shader decodes it.
fn plane(p: f32, s: f32, q: u8) -> f32 {
    p + f32::from(q) * s
}

/// The finest step exponent whose 255 steps from `p` reach `top`.
fn grid_exponent(p: f32, top: f32) -> u32 {
    let reaches = |e: u32| plane(p, step(e), u8::MAX) >= top;
    let extent = f64::from(top) - f64::from(p);
    let guess = if extent > 0.0 {
        ((extent / 255.0).log2().ceil() as i64 + 127).clamp(1, 254) as u32
    } else {
        1
    };
    let mut e = guess;
    while e < 254 && !reaches(e) {
        e += 1;
    }
    while e > 1 && reaches(e - 1) {
        e -= 1;
    }
    e
}

/// The largest byte whose plane is at or below `x` (`s` is a power of
/// two, so its reciprocal is exact; the guess is corrected in the
/// shader's arithmetic).
fn quantise_down(p: f32, s: f32, x: f32) -> u8 {
    let mut q = ((x - p) * s.recip()).floor().clamp(0.0, 255.0) as u8;
    while q > 0 && plane(p, s, q) > x {
        q -= 1;
    }
    q
}

/// The smallest byte whose plane is at or above `x` (255 at most: the
/// grid's exponent makes 255 reach the node's top).
fn quantise_up(p: f32, s: f32, x: f32) -> u8 {
    let mut q = ((x - p) * s.recip()).ceil().clamp(0.0, 255.0) as u8;
    while q < u8::MAX && plane(p, s, q) < x {
        q += 1;
    }
    q
}

/// Node `i` with exact child boxes, and its bounds; `bounds` must hold
/// those of its child nodes.
fn convert(
    cw: &CwBvh,
    triangles: &[RtTriangle],
    bounds: &[(Vec3A, Vec3A)],
    i: usize,
) -> (Node, (Vec3A, Vec3A)) {
    let node = &cw.nodes[i];
    let (mut lo, mut hi) = ([[f32::INFINITY; 8]; 3], [[f32::NEG_INFINITY; 8]; 3]);
    let (mut first, mut count) = ([0u32; 8], [0u8; 8]);
    let mut all = EMPTY;
    for c in (0..8).filter(|&c| !node.is_child_empty(c)) {
        let (bmin, bmax) = if node.is_leaf(c) {
            let (start, n) = node.child_primitives(c);
            first[c] = start;
            count[c] = n as u8;
            triangles[start as usize..(start + n) as usize]
                .iter()
                .map(|t| {
                    let a = t.aabb();
                    (a.min, a.max)
                })
                .fold(EMPTY, union)
        } else {
            first[c] = node.child_node_index(c);
            bounds[first[c] as usize]
        };
        for a in 0..3 {
            lo[a][c] = bmin[a];
            hi[a][c] = bmax[a];
        }
        all = union(all, (bmin, bmax));
    }
    let node = Node {
        lo: lo.map(f32x8::from),
        hi: hi.map(f32x8::from),
        first,
        count,
    };
    (node, all)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::{Scene, SceneOptions, engine::NodeLayout, shapes};

    /// Every child box of the benchmark mesh's tree decoded from its bytes
    /// contains the exact box and exceeds it by at most two grid steps a
    /// side; links, counts and empty slots survive the packing.
    #[test]
    fn quantised_boxes_contain_the_exact_ones_and_stay_tight() {
        let mesh = shapes::timing_mesh();
        let scene = Scene::new(&mesh.positions, &mesh.triangles, &SceneOptions::default()).unwrap();
        let exact = scene.gpu_nodes(NodeLayout::Exact);
        let packed = scene.gpu_nodes(NodeLayout::Quantised);
        let nodes = exact.len() / GPU_NODE_WORDS;
        assert!(nodes > 1000);
        assert_eq!(packed.len(), nodes * GPU_QUANTISED_NODE_WORDS);
        let (mut children, mut loose) = (0, 0.0f64);
        for n in 0..nodes {
            let x = &exact[n * GPU_NODE_WORDS..(n + 1) * GPU_NODE_WORDS];
            let q = &packed[n * GPU_QUANTISED_NODE_WORDS..(n + 1) * GPU_QUANTISED_NODE_WORDS];
            let counts: Vec<u8> = x[56..58].iter().flat_map(|w| w.to_le_bytes()).collect();
            for c in 0..8 {
                let word = q[4 + c];
                let count = word >> 29;
                if counts[c] == u8::MAX {
                    assert_eq!(count, QUANTISED_EMPTY, "node {n} child {c}");
                    continue;
                }
                assert_eq!(count, u32::from(counts[c]));
                assert_eq!(word & ((1 << 29) - 1), x[48 + c]);
                children += 1;
                for a in 0..3 {
                    let s = step((q[3] >> (8 * a)) & 0xff);
                    let (lo, hi) = (
                        f32::from_bits(x[8 * a + c]),
                        f32::from_bits(x[8 * (a + 3) + c]),
                    );
                    let (qlo, qhi) = (decoded(q, a, c, false), decoded(q, a + 3, c, false));
                    assert!(qlo <= lo && qhi >= hi, "node {n} child {c} axis {a}");
                    assert!(lo - qlo <= 2.0 * s && qhi - hi <= 2.0 * s);
                    loose += f64::from((qhi - qlo) - (hi - lo)) / f64::from(255.0 * s);
                }
            }
        }
        // On average each axis grows by about a step in 255 of the grid.
        let mean = loose / (3 * children) as f64;
        assert!(
            mean < 2.0 / 255.0,
            "boxes grew by {mean} of their node's extent"
        );
    }

    /// Planes decoded from a node's bytes, as the shader decodes them:
    /// IEEE, or with subnormal inputs and results flushed to zero.
    fn decoded(words: &[u32], field: usize, c: usize, flush: bool) -> f32 {
        let ftz = |x: f32| if flush && x.is_subnormal() { 0.0 } else { x };
        let a = field % 3;
        let p = ftz(f32::from_bits(words[a]));
        let s = step((words[3] >> (8 * a)) & 0xff);
        let q = words[12 + 2 * field + c / 4].to_le_bytes()[c % 4];
        ftz(plane(p, s, q))
    }

    /// Degenerate children: a point, a flat box, boxes in the subnormal
    /// band and straddling zero, far from the origin, and empty slots.
    #[test]
    fn degenerate_and_subnormal_boxes_stay_contained_flushed_or_not() {
        let tiny = f32::MIN_POSITIVE / 4.0;
        let boxes: [([f32; 3], [f32; 3]); 6] = [
            ([0.25; 3], [0.25; 3]),
            ([-1.0, 0.5, 0.5], [1.0, 0.5, 0.5]),
            ([-tiny, tiny, -tiny], [tiny, 2.0 * tiny, -tiny / 2.0]),
            ([-3.0 * tiny, -1e-30, 0.0], [-tiny, 1e-30, tiny]),
            ([1e6, -1e6, 3.0], [1e6 + 1.0, -1e6 + 0.5, 3.0]),
            ([0.0; 3], [1e-3; 3]),
        ];
        let mut node = EMPTY_NODE;
        for (c, (lo, hi)) in boxes.iter().enumerate() {
            let (mut l, mut h) = (node.lo.map(|v| v.to_array()), node.hi.map(|v| v.to_array()));
            for a in 0..3 {
                l[a][c] = lo[a];
                h[a][c] = hi[a];
            }
            node.lo = l.map(f32x8::from);
            node.hi = h.map(f32x8::from);
            node.first[c] = 10 * c as u32;
            node.count[c] = (c % 4) as u8;
        }
        let words = quantised_node(&node);
        for (c, (lo, hi)) in boxes.iter().enumerate() {
            assert_eq!(words[4 + c] >> 29, (c % 4) as u32);
            assert_eq!(words[4 + c] & ((1 << 29) - 1), 10 * c as u32);
            for flush in [false, true] {
                for a in 0..3 {
                    let (ql, qh) = (
                        decoded(&words, a, c, flush),
                        decoded(&words, a + 3, c, flush),
                    );
                    assert!(
                        ql <= lo[a] && qh >= hi[a],
                        "child {c} axis {a} flush {flush}: [{ql}, {qh}] against [{}, {}]",
                        lo[a],
                        hi[a]
                    );
                }
            }
        }
        for c in boxes.len()..8 {
            assert_eq!(words[4 + c] >> 29, QUANTISED_EMPTY);
        }
        // An all-empty node still packs (any grid; every slot empty).
        let empty = quantised_node(&EMPTY_NODE);
        assert!((0..8).all(|c| empty[4 + c] >> 29 == QUANTISED_EMPTY));
    }
}
