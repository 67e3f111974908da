//! A lightmap atlas of the character and its texels as surface points.
//!
//! The atlas is generated from the bind-pose mesh by uvunwrap (pure Rust,
//! `forbid(unsafe_code)`, bit-identical output on any thread count and,
//! without its `direct-solver` feature, on any platform): xatlas's
//! charting, LSCM and ARAP parameterisation and shape packing, with
//! padding between charts. Every character gets one, whatever UVs it
//! came with (none, palette UVs, mirrored halves), and the same mesh
//! always gets the same atlas.
//!
//! **Texels.** A texel whose centre lies in a triangle's UV image is that
//! surface point (inside). A texel whose centre lies within a diagonal of
//! a triangle is the nearest point of the nearest such triangle (border):
//! bilinear filtering anywhere on a chart reads the four texel centres
//! within one texel of it along each axis, each of those is inside or
//! border, so it reads traced values, never padding (charts are four
//! texels apart, so no border texel is near two). The texels beyond
//! are padding: [`dilate`] fills them from their neighbours so that
//! mipmaps do not bleed the background into the charts.
//!
//! A texel is posed with the mesh by its barycentric coordinates on the
//! posed triangle: the very point the rasteriser shows there.

use aobake_runtime::method::texel::AtlasLayout;
pub use aobake_runtime::method::texel::dilate;
use std::ops::ControlFlow;

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// A texel bake's atlas side (texels) when the request names none: the
/// smallest power of two at which every shared character's texel floor
/// (exact AO at the texel centres, bilinearly filtered) is under half of
/// GTAO's per-pixel error: 0.039 (Kenney), 0.012 (Fox), 0.012
/// (CesiumMan), 0.028 (the milk truck) against 0.108, 0.085, 0.112 and
/// 0.084; at 128 the Kenney character's and the truck's are not (0.066,
/// 0.081) (`aobake bench preview --texel-floor`, docs/methods/texel.md).
/// 512 halves the floors again, but takes the fit past 2 GB on the Kenney
/// character until it streams.
pub const DEFAULT_ATLAS: u32 = 256;

/// Empty texels around each chart (charts are at least twice this apart):
/// two keep bilinear filtering and one mip level free of bleeding once
/// the padding is dilated.
pub const PADDING: u32 = 2;

/// The smallest and largest atlas sides accepted.
pub const SIZES: std::ops::RangeInclusive<u32> = 16..=4096;

/// How an atlas is generated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct AtlasOptions {
    /// The page's side in texels: the densest packing that fits one page
    /// of this width (its height is cropped to the rows used).
    pub size: u32,
    /// Empty texels around each chart.
    pub padding: u32,
}

/// Texel centres per texel of the page that an atlas's walks may visit
/// ([`Atlas::check_walk`]).
const WALK_PER_TEXEL: f64 = 8.0;
/// Texel centres per triangle that an atlas's walks may visit besides.
const WALK_PER_TRIANGLE: f64 = 32.0;

impl Default for AtlasOptions {
    fn default() -> Self {
        Self {
            size: DEFAULT_ATLAS,
            padding: PADDING,
        }
    }
}

/// Why no atlas was made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AtlasError {
    /// The size is outside [`SIZES`] or leaves no room inside the padding.
    #[error(
        "an atlas of {size} texels with {padding} of padding: the side must be {}..={} and more than 4 × the padding",
        SIZES.start(),
        SIZES.end()
    )]
    Size {
        /// The side asked for.
        size: u32,
        /// The padding asked for.
        padding: u32,
    },
    /// The mesh has no triangle with area.
    #[error("the mesh has no triangle with area to put in an atlas")]
    Empty,
    /// The unwrapper refused the mesh.
    #[error("the atlas could not be generated: {0}")]
    Unwrap(String),
    /// A UV of the character's own set lies outside the page.
    #[error(
        "TEXCOORD_{set} of vertex {vertex} is ({}, {}), outside [0, 1]²: a texel atlas gives every place of the surface its own texel, so UVs that tile or wrap cannot be one (leave texel.uv_set out for a generated atlas)",
        uv[0],
        uv[1]
    )]
    UvOutside {
        /// The set.
        set: u32,
        /// The vertex (aobake's order).
        vertex: usize,
        /// Its UV.
        uv: [f32; 2],
    },
    /// Two places of the surface share a texel of the character's own set.
    #[error(
        "TEXCOORD_{set} puts triangles {} and {} (aobake's order) on the same texel ({}, {}) of a {size}-texel atlas, two places of the surface on one texel (mirrored or shared UVs): leave texel.uv_set out for a generated atlas",
        triangles[0],
        triangles[1],
        texel[0],
        texel[1]
    )]
    Overlap {
        /// The set.
        set: u32,
        /// The atlas side.
        size: u32,
        /// The texel (column, row).
        texel: [u32; 2],
        /// The two triangles.
        triangles: [u32; 2],
    },
    /// The triangles' UVs cover the page many times over (UVs that stack
    /// triangles on one another): finding their texels would cost too
    /// much.
    #[error(
        "the UVs' triangles cover {boxes:.0} texel centres of a page of {page}: they stack many times over, as no atlas does"
    )]
    Overdrawn {
        /// Texel centres the triangles' boxes (with reach) hold, summed.
        boxes: f64,
        /// Texels of the page.
        page: u64,
    },
    /// A texel asset's atlas places its columns on other texels than
    /// its UVs give.
    #[error(
        "the asset's texels are not the ones its atlas's UVs give (written by another atlas version, or edited)"
    )]
    Texels,
    /// The charts did not fit one page.
    #[error(
        "the charts need {pages} pages of {size} texels: use a larger atlas (each chart needs {padding} texels of padding)"
    )]
    Pages {
        /// Pages the unwrapper used.
        pages: u32,
        /// The side asked for.
        size: u32,
        /// The padding asked for.
        padding: u32,
    },
}

/// A UV atlas of a triangle mesh: the mesh's triangles in its order, over
/// vertices split where charts meet.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Atlas {
    /// Texels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Charts.
    pub charts: u32,
    /// Per atlas vertex, the mesh vertex it was made from.
    pub xref: Vec<u32>,
    /// Per atlas vertex, its texture coordinate in `[0, 1]²`: `(0, 0)` is
    /// the outer corner of texel row 0, column 0, and `v` grows with the
    /// row (wgpu's, Vulkan's and glTF's convention).
    pub uvs: Vec<Vec2>,
    /// The mesh's triangles in its order, corner for corner, indexing the
    /// atlas vertices.
    pub triangles: Vec<[u32; 3]>,
}

impl Atlas {
    /// Unwraps the mesh (`positions`, `triangles`: the bind pose) into one
    /// page. Deterministic: the same mesh and options give the same atlas.
    pub fn generate(
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        options: &AtlasOptions,
    ) -> Result<Self, AtlasError> {
        let AtlasOptions { size, padding } = *options;
        if !SIZES.contains(&size) || size <= 4 * padding {
            return Err(AtlasError::Size { size, padding });
        }
        let area = |t: &[u32; 3]| {
            let [a, b, c] = t.map(|i| positions.get(i as usize).copied().unwrap_or(Vec3::ZERO));
            (b - a).cross(c - a).length()
        };
        if !triangles.iter().any(|t| area(t) > 0.0) {
            return Err(AtlasError::Empty);
        }
        let points: Vec<[f32; 3]> = positions.iter().map(|p| p.to_array()).collect();
        let indices: Vec<u32> = triangles.iter().flatten().copied().collect();
        let input = uvunwrap::MeshInput::new(&points, &indices);
        let unwrap_options = uvunwrap::Options {
            density: uvunwrap::Density::Auto { page_size: size },
            padding,
            ..uvunwrap::Options::default()
        };
        let out = uvunwrap::generate(&[input], &unwrap_options)
            .map_err(|e| AtlasError::Unwrap(e.to_string()))?;
        if out.page_count != 1 {
            return Err(AtlasError::Pages {
                pages: out.page_count,
                size,
                padding,
            });
        }
        let mesh = out
            .meshes
            .into_iter()
            .next()
            .ok_or_else(|| AtlasError::Unwrap("no mesh came back".into()))?;
        if mesh.indices.len() != indices.len() {
            return Err(AtlasError::Unwrap(format!(
                "{} corners came back for {}",
                mesh.indices.len(),
                indices.len()
            )));
        }
        Ok(Self {
            width: out.width,
            height: out.height,
            charts: out.chart_count,
            xref: mesh.vertices.iter().map(|v| v.xref).collect(),
            uvs: mesh.vertices.iter().map(|v| Vec2::from(v.uv)).collect(),
            triangles: mesh
                .indices
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
        })
    }

    /// An atlas of the mesh's own UV set `set` (`uvs`, one per vertex) at
    /// `size` × `size` texels: used as it is when every UV lies in the
    /// page and no texel centre falls on two places of the surface (a
    /// texel on an edge two triangles share is one place); refused
    /// otherwise, naming the first UV or texel at fault. Its charts are
    /// the UV islands (triangles joined by shared vertices); the padding
    /// between them is the file's.
    pub fn from_uv_set(
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        (set, uvs): (u32, &[Vec2]),
        size: u32,
    ) -> Result<Self, AtlasError> {
        if !SIZES.contains(&size) {
            return Err(AtlasError::Size { size, padding: 0 });
        }
        if let Some((vertex, uv)) = uvs.iter().enumerate().find(|(_, uv)| {
            !(uv.is_finite() && uv.cmpge(Vec2::ZERO).all() && uv.cmple(Vec2::ONE).all())
        }) {
            return Err(AtlasError::UvOutside {
                set,
                vertex,
                uv: uv.to_array(),
            });
        }
        let atlas = Self {
            width: size,
            height: size,
            charts: islands(triangles, uvs.len()),
            xref: (0..uvs.len() as u32).collect(),
            uvs: uvs.to_vec(),
            triangles: triangles.to_vec(),
        };
        atlas.check_walk()?;
        match atlas.overlap(positions) {
            Some((texel, triangles)) => Err(AtlasError::Overlap {
                set,
                size,
                texel,
                triangles,
            }),
            None => Ok(atlas),
        }
    }

    /// The first texel (column, row) whose centre lies in two triangles at
    /// two places of the surface (`positions`, the mesh's vertices), and
    /// those triangles.
    fn overlap(&self, positions: &[Vec3]) -> Option<([u32; 2], [u32; 2])> {
        let (w, h) = (self.width as usize, self.height as usize);
        let (lo, hi) =
            crate::geometry::bounds(positions.iter().copied()).unwrap_or((Vec3::ZERO, Vec3::ZERO));
        let same = 1e-4 * (hi - lo).length();
        let mut first: Vec<Option<(u32, Vec3)>> = vec![None; w * h];
        let found = self.walk_centres(0.0, |t, i, bary, _| {
            let [a, b, c] = self.triangles[t].map(|v| positions[self.xref[v as usize] as usize]);
            let p = a * bary.x + b * bary.y + c * bary.z;
            match first[i] {
                None => first[i] = Some((t as u32, p)),
                Some((u, q)) if q.distance(p) > same => {
                    return ControlFlow::Break((i, [u, t as u32]));
                }
                Some(_) => {}
            }
            ControlFlow::Continue(())
        });
        found.map(|(i, triangles)| ([(i % w) as u32, (i / w) as u32], triangles))
    }

    /// Refuses an atlas whose texel walks ([`Atlas::walk_centres`], with
    /// up to a diagonal's reach) would visit more than
    /// [`WALK_PER_TEXEL`] centres per texel of the page, plus
    /// [`WALK_PER_TRIANGLE`] per triangle: real atlases visit a few per
    /// texel; a hostile one stacking every triangle over the page would
    /// cost triangles × page.
    fn check_walk(&self) -> Result<(), AtlasError> {
        let reach = std::f32::consts::SQRT_2;
        let (w, h) = (self.width as f64, self.height as f64);
        let mut boxes = 0.0f64;
        for t in 0..self.triangles.len() {
            let [a, b, c] = self.corners(t);
            let lo = (a.min(b).min(c) - Vec2::splat(reach)).max(Vec2::ZERO);
            let hi = (a.max(b).max(c) + Vec2::splat(reach)).min(Vec2::new(w as f32, h as f32));
            let side = (hi - lo).max(Vec2::ZERO);
            boxes += f64::from(side.x + 1.0) * f64::from(side.y + 1.0);
        }
        let page = self.width as u64 * self.height as u64;
        let budget = WALK_PER_TEXEL * page as f64 + WALK_PER_TRIANGLE * self.triangles.len() as f64;
        // A box that is not a number is refused too.
        if boxes.is_nan() || boxes > budget {
            return Err(AtlasError::Overdrawn { boxes, page });
        }
        Ok(())
    }

    /// Walks the texel centres within `reach` texels of each triangle with
    /// area in UV, triangle by triangle in order: `visit(triangle, texel,
    /// barycentrics of the triangle's point nearest the centre, its
    /// distance in texels, 0 inside)`, until `visit` breaks with a value.
    fn walk_centres<B>(
        &self,
        reach: f32,
        mut visit: impl FnMut(usize, usize, Vec3, f32) -> ControlFlow<B>,
    ) -> Option<B> {
        let (w, h) = (self.width as usize, self.height as usize);
        for t in 0..self.triangles.len() {
            let [a, b, c] = self.corners(t);
            let area = (b - a).perp_dot(c - a);
            if area == 0.0 || !area.is_finite() {
                continue;
            }
            let lo = a.min(b).min(c) - Vec2::splat(reach);
            let hi = a.max(b).max(c) + Vec2::splat(reach);
            // Texel centres (x + ½, y + ½) within the reach of the triangle.
            let first = |lo: f32| (lo - 0.5).ceil().max(0.0) as i64;
            let last = |hi: f32, n: usize| ((hi - 0.5).floor() as i64).min(n as i64 - 1);
            for y in first(lo.y)..=last(hi.y, h) {
                for x in first(lo.x)..=last(hi.x, w) {
                    let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                    let (bary, distance) = nearest_on_triangle(centre, [a, b, c], area);
                    if distance <= reach
                        && let ControlFlow::Break(b) =
                            visit(t, y as usize * w + x as usize, bary, distance)
                    {
                        return Some(b);
                    }
                }
            }
        }
        None
    }

    /// The texture coordinate of the point with barycentric coordinates
    /// `bary` (weights of the corners, in order) on triangle `triangle`.
    pub fn uv(&self, triangle: usize, bary: Vec3) -> Vec2 {
        let [a, b, c] = self.triangles[triangle].map(|i| self.uvs[i as usize]);
        a * bary.x + b * bary.y + c * bary.z
    }

    /// A triangle's corners in texel units.
    fn corners(&self, triangle: usize) -> [Vec2; 3] {
        let scale = Vec2::new(self.width as f32, self.height as f32);
        self.triangles[triangle].map(|i| self.uvs[i as usize] * scale)
    }

    /// The texels that show the surface, row-major: inside texels and the
    /// border texels around every chart (see the module's notes).
    pub fn texels(&self) -> Texels {
        let (w, h) = (self.width as usize, self.height as usize);
        // Per texel: (triangle, barycentrics, distance in texels; 0 inside).
        let mut best: Vec<Option<(u32, Vec3, f32)>> = vec![None; w * h];
        // A bilinear read anywhere on a chart takes the four centres within
        // one texel of it along each axis, up to a diagonal away.
        self.walk_centres(std::f32::consts::SQRT_2, |t, i, bary, distance| {
            // The nearest triangle wins; among equals (inside several, on
            // a shared edge) the first.
            let slot = &mut best[i];
            if slot.is_none_or(|(_, _, d)| distance < d) {
                *slot = Some((t as u32, bary, distance));
            }
            ControlFlow::<()>::Continue(())
        });
        let texels = best
            .iter()
            .enumerate()
            .filter_map(|(i, s)| {
                s.map(|(triangle, bary, distance)| Texel {
                    index: i as u32,
                    triangle,
                    bary: bary.to_array(),
                    inside: distance == 0.0,
                })
            })
            .collect();
        Texels {
            width: self.width,
            height: self.height,
            texels,
        }
    }
}

/// An atlas with its texels, as the texel methods and the per-pixel
/// judge use it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TexelAtlas {
    /// The atlas.
    pub atlas: Atlas,
    /// Its texels that show the surface.
    pub texels: Texels,
}

impl TexelAtlas {
    /// The atlas of a mesh ([`Atlas::generate`]) and its texels.
    pub fn generate(
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        options: &AtlasOptions,
    ) -> Result<Self, AtlasError> {
        let atlas = Atlas::generate(positions, triangles, options)?;
        let texels = atlas.texels();
        Ok(Self { atlas, texels })
    }

    /// The atlas as an asset stores it, its columns these texels.
    pub fn layout(&self) -> AtlasLayout {
        let a = &self.atlas;
        AtlasLayout {
            width: a.width,
            height: a.height,
            xref: a.xref.clone(),
            uvs: a.uvs.iter().map(|uv| uv.to_array()).collect(),
            triangles: a.triangles.clone(),
            texels: self.texels.texels.iter().map(|t| t.index).collect(),
        }
    }

    /// The generated atlas of a character at rest, as its scene places it
    /// (two nodes instancing one mesh, or a part its node mirrors or
    /// scales, are two places of the surface, each at its own size; the
    /// merged mesh holds each instance in its mesh's own space).
    pub fn of_character(
        character: &crate::Character,
        options: &AtlasOptions,
    ) -> Result<Self, AtlasError> {
        Self::generate(&rest_positions(character), &character.triangles, options)
    }

    /// The atlas a texel asset stores, with its texels: they must be the
    /// asset's columns (`layout.texels`), as the bake that wrote it found
    /// them. How a texel asset is previewed and judged per pixel.
    pub fn from_layout(layout: &AtlasLayout) -> Result<Self, AtlasError> {
        let atlas = Atlas {
            width: layout.width,
            height: layout.height,
            charts: islands(&layout.triangles, layout.xref.len()),
            xref: layout.xref.clone(),
            uvs: layout.uvs.iter().map(|&uv| Vec2::from(uv)).collect(),
            triangles: layout.triangles.clone(),
        };
        atlas.check_walk()?;
        let texels = atlas.texels();
        if !texels
            .texels
            .iter()
            .map(|t| t.index)
            .eq(layout.texels.iter().copied())
        {
            return Err(AtlasError::Texels);
        }
        Ok(Self { atlas, texels })
    }

    /// The atlas of a UV set of the mesh's own ([`Atlas::from_uv_set`])
    /// and its texels.
    pub fn of_uv_set(
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        set: (u32, &[Vec2]),
        size: u32,
    ) -> Result<Self, AtlasError> {
        let atlas = Atlas::from_uv_set(positions, triangles, set, size)?;
        let texels = atlas.texels();
        Ok(Self { atlas, texels })
    }

    /// Per-texel `values` filtered as a GPU's linear sampler filters the
    /// dilated image, at the point with barycentric coordinates `bary` on
    /// `triangle`.
    pub fn sample(&self, image: &[f32], triangle: usize, bary: Vec3) -> f32 {
        let uv = self.atlas.uv(triangle, bary);
        bilinear(image, self.atlas.width, self.atlas.height, uv)
    }
}

/// A texel that shows a point of the surface.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Texel {
    /// `row × width + column`.
    pub index: u32,
    /// The triangle (the mesh's order) the point lies on.
    pub triangle: u32,
    /// The point's barycentric coordinates on it (corner weights, in
    /// order; they sum to 1).
    pub bary: [f32; 3],
    /// The texel's centre lies inside the triangle's UV image (else the
    /// texel is on a chart's border and shows the nearest point).
    pub inside: bool,
}

/// The texels of an atlas that show the surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Texels {
    /// Texels per row of the atlas.
    pub width: u32,
    /// Rows of the atlas.
    pub height: u32,
    /// Row-major.
    pub texels: Vec<Texel>,
}

impl Texels {
    /// Number of texels that show the surface.
    pub fn len(&self) -> usize {
        self.texels.len()
    }

    /// No texel shows the surface.
    pub fn is_empty(&self) -> bool {
        self.texels.is_empty()
    }

    /// The share of the atlas's texels whose centre lies on the surface.
    pub fn utilisation(&self) -> f64 {
        let inside = self.texels.iter().filter(|t| t.inside).count();
        inside as f64 / (f64::from(self.width) * f64::from(self.height)).max(1.0)
    }

    /// Every texel's point and unit normal on a posed mesh (`positions`
    /// and unit `normals` per mesh vertex, the mesh's `triangles`): the
    /// barycentric blend of its triangle's corners, the normal
    /// renormalised (the face's where the blend vanishes).
    pub fn points(
        &self,
        positions: &[Vec3],
        normals: &[Vec3],
        triangles: &[[u32; 3]],
    ) -> (Vec<Vec3>, Vec<Vec3>) {
        self.texels
            .iter()
            .map(|t| {
                let corners = triangles[t.triangle as usize].map(|i| i as usize);
                let [pa, pb, pc] = corners.map(|i| positions[i]);
                let [na, nb, nc] = corners.map(|i| normals[i]);
                let [u, v, w] = t.bary;
                let p = pa * u + pb * v + pc * w;
                let face = (pb - pa).cross(pc - pa).normalize_or(Vec3::Y);
                let n = (na * u + nb * v + nc * w).normalize_or(face);
                (p, n)
            })
            .unzip()
    }

    /// The atlas image of per-texel `values` (in [`Texels::texels`]'s
    /// order), its padding dilated from the charts.
    pub fn image(&self, values: &[f32]) -> Vec<f32> {
        aobake_runtime::method::texel::texture(
            self.width,
            self.height,
            self.texels.iter().map(|t| t.index),
            values,
        )
    }
}

/// The character's vertices at rest, where its scene places them.
pub fn rest_positions(character: &crate::Character) -> Vec<Vec3> {
    character
        .skin(&crate::Pose::rest(&character.skeleton))
        .positions
}

/// The islands of a triangle mesh over `vertices` vertices: groups of
/// triangles joined by shared vertices (a UV set's charts, its vertices
/// split where UVs are).
fn islands(triangles: &[[u32; 3]], vertices: usize) -> u32 {
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let mut parent: Vec<usize> = (0..vertices).collect();
    for t in triangles {
        let a = root(&mut parent, t[0] as usize);
        for &v in &t[1..] {
            let b = root(&mut parent, v as usize);
            parent[b] = a;
        }
    }
    let mut used = vec![false; vertices];
    triangles
        .iter()
        .flatten()
        .for_each(|&v| used[v as usize] = true);
    (0..vertices)
        .filter(|&v| used[v] && root(&mut parent, v) == v)
        .count() as u32
}

/// Bilinear filtering as a GPU's linear sampler filters (the runtime's,
/// as engines evaluate texel assets), at `uv`.
pub fn bilinear(image: &[f32], width: u32, height: u32, uv: Vec2) -> f32 {
    aobake_runtime::method::texel::bilinear(image, width, height, uv.to_array())
}

/// Barycentric coordinates of `p` on a triangle of 3D corners, from the
/// projection of `p` on its plane, clamped into the triangle: the point
/// of the triangle nearest `p`'s projection.
pub fn barycentric(p: Vec3, [a, b, c]: [Vec3; 3]) -> Vec3 {
    let (e1, e2, d) = (b - a, c - a, p - a);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1, d2) = (d.dot(e1), d.dot(e2));
    let det = d11 * d22 - d12 * d12;
    if det == 0.0 || !det.is_finite() {
        return Vec3::new(1.0, 0.0, 0.0);
    }
    let v = (d22 * d1 - d12 * d2) / det;
    let w = (d11 * d2 - d12 * d1) / det;
    let bary = Vec3::new(1.0 - v - w, v, w).max(Vec3::ZERO);
    bary / bary.element_sum().max(f32::MIN_POSITIVE)
}

/// The point of triangle `[a, b, c]` (2D, signed double area `area`)
/// nearest `p`: its barycentric coordinates and its distance (0 inside).
fn nearest_on_triangle(p: Vec2, [a, b, c]: [Vec2; 3], area: f32) -> (Vec3, f32) {
    let wa = (b - p).perp_dot(c - p) / area;
    let wb = (c - p).perp_dot(a - p) / area;
    let wc = 1.0 - wa - wb;
    if wa >= 0.0 && wb >= 0.0 && wc >= 0.0 {
        return (Vec3::new(wa, wb, wc), 0.0);
    }
    // Outside: the nearest point lies on one of the edges.
    let edge = |(s, t): (Vec2, Vec2)| {
        let d = t - s;
        let f = ((p - s).dot(d) / d.length_squared().max(f32::MIN_POSITIVE)).clamp(0.0, 1.0);
        (f, p.distance(s + d * f))
    };
    let (fab, dab) = edge((a, b));
    let (fbc, dbc) = edge((b, c));
    let (fca, dca) = edge((c, a));
    if dab <= dbc && dab <= dca {
        (Vec3::new(1.0 - fab, fab, 0.0), dab)
    } else if dbc <= dca {
        (Vec3::new(0.0, 1.0 - fbc, fbc), dbc)
    } else {
        (Vec3::new(fca, 0.0, 1.0 - fca), dca)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube's 12 triangles over 8 shared corners (outward faces).
    fn cube() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let positions = (0..8)
            .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
            .collect();
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let triangles = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        (positions, triangles)
    }

    #[test]
    fn a_cube_unwraps_into_one_page_the_same_way_every_time() {
        let (positions, triangles) = cube();
        let options = AtlasOptions {
            size: 64,
            padding: 2,
        };
        let atlas = Atlas::generate(&positions, &triangles, &options).unwrap();
        assert_eq!(
            atlas,
            Atlas::generate(&positions, &triangles, &options).unwrap()
        );
        assert_eq!(atlas.width, 64);
        assert!(atlas.height <= 64);
        assert_eq!(atlas.triangles.len(), triangles.len());
        // Corners keep their mesh vertex.
        for (t, at) in triangles.iter().zip(&atlas.triangles) {
            for k in 0..3 {
                assert_eq!(atlas.xref[at[k] as usize], t[k]);
            }
        }
        assert!(
            atlas
                .uvs
                .iter()
                .all(|uv| (0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y))
        );
        // The six faces' texels: about a sixth of the page each at most,
        // and every face gets some.
        let texels = atlas.texels();
        let mut per_face = [0usize; 6];
        for t in &texels.texels {
            per_face[t.triangle as usize / 2] += t.inside as usize;
        }
        assert!(per_face.iter().all(|&n| n > 16), "{per_face:?}");
        assert!(texels.utilisation() > 0.2, "{}", texels.utilisation());
    }

    #[test]
    fn no_texel_shows_two_places_and_each_point_lies_on_its_triangle() {
        let (positions, triangles) = cube();
        let atlas = Atlas::generate(
            &positions,
            &triangles,
            &AtlasOptions {
                size: 48,
                padding: 2,
            },
        )
        .unwrap();
        let texels = atlas.texels();
        let mut seen = std::collections::HashSet::new();
        for t in &texels.texels {
            assert!(seen.insert(t.index), "texel {} listed twice", t.index);
            let b = Vec3::from(t.bary);
            assert!((b.element_sum() - 1.0).abs() < 1e-5 && b.min_element() >= 0.0);
            // The texel's point maps back into (or next to) the texel.
            let uv = atlas.uv(t.triangle as usize, b) * Vec2::new(48.0, atlas.height as f32);
            let centre = Vec2::new((t.index % 48) as f32 + 0.5, (t.index / 48) as f32 + 0.5);
            let reach = if t.inside { 1e-3 } else { 1.415 };
            assert!(uv.distance(centre) <= reach, "{uv} {centre} {}", t.inside);
        }
        // Posed at rest, the points lie on the cube's faces.
        let normals: Vec<Vec3> = positions.iter().map(|p| (*p - 0.5).normalize()).collect();
        let (points, _) = texels.points(&positions, &normals, &triangles);
        for p in points {
            let on_face = (0..3).any(|a| p[a].abs() < 1e-5 || (p[a] - 1.0).abs() < 1e-5);
            assert!(
                on_face && p.min_element() > -1e-5 && p.max_element() < 1.0 + 1e-5,
                "{p}"
            );
        }
    }

    #[test]
    fn dilation_fills_the_padding_from_the_charts() {
        // A 4 × 3 image with one filled texel in a corner and one in the
        // middle of the bottom row.
        let mut image = vec![0.0; 12];
        let mut filled = vec![false; 12];
        (image[0], filled[0]) = (1.0, true);
        (image[10], filled[10]) = (3.0, true);
        dilate(&mut image, &mut filled, 4, 3);
        assert!(filled.iter().all(|&f| f));
        assert_eq!(image[1], 1.0);
        assert_eq!(image[5], 2.0, "between both: the mean");
        assert_eq!(image[11], 3.0);
    }

    #[test]
    fn bilinear_filtering_matches_a_gpu_sampler() {
        let image = [0.0, 1.0, 2.0, 3.0];
        // Texel centres give their values; halfway between, the mean;
        // outside, the edge.
        assert_eq!(bilinear(&image, 2, 2, Vec2::new(0.25, 0.25)), 0.0);
        assert_eq!(bilinear(&image, 2, 2, Vec2::new(0.75, 0.75)), 3.0);
        assert_eq!(bilinear(&image, 2, 2, Vec2::new(0.5, 0.25)), 0.5);
        assert_eq!(bilinear(&image, 2, 2, Vec2::new(0.5, 0.5)), 1.5);
        assert_eq!(bilinear(&image, 2, 2, Vec2::new(0.0, 0.0)), 0.0);
        assert_eq!(bilinear(&image, 2, 2, Vec2::new(1.0, 0.25)), 1.0);
    }

    #[test]
    fn barycentric_coordinates_recover_a_point_and_clamp_outside() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let b = barycentric(Vec3::new(0.25, 0.5, 0.3), tri);
        assert!((b - Vec3::new(0.25, 0.25, 0.5)).length() < 1e-6, "{b}");
        let b = barycentric(Vec3::new(2.0, -1.0, 0.0), tri);
        assert_eq!(b, Vec3::new(0.0, 1.0, 0.0));
    }

    #[test]
    fn a_uv_set_is_used_as_it_is_unless_it_leaves_the_page_or_overlaps() {
        // Two unit squares side by side in space (x 0..1 and 2..3), each
        // its own four vertices.
        let positions: Vec<Vec3> = [0.0, 2.0]
            .iter()
            .flat_map(|&x| {
                [
                    Vec3::new(x, 0.0, 0.0),
                    Vec3::new(x + 1.0, 0.0, 0.0),
                    Vec3::new(x + 1.0, 1.0, 0.0),
                    Vec3::new(x, 1.0, 0.0),
                ]
            })
            .collect();
        let triangles = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let square = |x: f32| {
            [
                Vec2::new(x, 0.1),
                Vec2::new(x + 0.4, 0.1),
                Vec2::new(x + 0.4, 0.5),
                Vec2::new(x, 0.5),
            ]
        };
        // Apart on the page: used as it is, two charts.
        let apart: Vec<Vec2> = square(0.05).into_iter().chain(square(0.55)).collect();
        let atlas = TexelAtlas::of_uv_set(&positions, &triangles, (0, &apart), 32).unwrap();
        assert_eq!(atlas.atlas.uvs, apart);
        assert_eq!((atlas.atlas.width, atlas.atlas.charts), (32, 2));
        assert!(atlas.texels.len() > 2 * 12 * 12);
        // Mirrored (both squares on the same UVs): refused, naming a
        // triangle of each square.
        let shared: Vec<Vec2> = square(0.05).into_iter().chain(square(0.05)).collect();
        match Atlas::from_uv_set(&positions, &triangles, (1, &shared), 32) {
            Err(AtlasError::Overlap {
                set: 1, triangles, ..
            }) => {
                assert!(triangles[0] < 2 && triangles[1] >= 2, "{triangles:?}")
            }
            other => panic!("{other:?}"),
        }
        // Tiling UVs: refused, naming the vertex.
        let mut tiled = apart.clone();
        tiled[5].x = 1.5;
        assert!(matches!(
            Atlas::from_uv_set(&positions, &triangles, (0, &tiled), 32),
            Err(AtlasError::UvOutside { vertex: 5, .. })
        ));
        let message = Atlas::from_uv_set(&positions, &triangles, (1, &shared), 32)
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("TEXCOORD_1") && message.contains("uv_set"),
            "{message}"
        );
    }

    #[test]
    fn an_assets_layout_gives_back_its_atlas_and_an_edited_one_is_refused() {
        let (positions, triangles) = cube();
        let options = AtlasOptions {
            size: 64,
            padding: 2,
        };
        let made = TexelAtlas::generate(&positions, &triangles, &options).unwrap();
        let layout = made.layout();
        let back = TexelAtlas::from_layout(&layout).unwrap();
        assert_eq!(back.texels, made.texels);
        assert_eq!(back.layout(), layout);
        // Columns on other texels than the UVs give.
        let mut moved = layout.clone();
        moved.texels.swap(0, 1);
        assert_eq!(TexelAtlas::from_layout(&moved), Err(AtlasError::Texels));
        let mut shrunk = layout;
        shrunk.uvs.iter_mut().for_each(|uv| uv[0] *= 0.5);
        assert_eq!(TexelAtlas::from_layout(&shrunk), Err(AtlasError::Texels));
    }

    #[test]
    fn uvs_that_stack_triangles_over_the_page_are_refused_before_the_walk() {
        // 400 triangles, each over half the page, each its own place.
        let n = 400;
        let positions: Vec<Vec3> = (0..3 * n)
            .map(|i| Vec3::new(i as f32, (i % 3) as f32, 0.0))
            .collect();
        let triangles: Vec<[u32; 3]> = (0..n as u32)
            .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
            .collect();
        let uvs: Vec<Vec2> = (0..n)
            .flat_map(|_| [Vec2::ZERO, Vec2::X, Vec2::Y])
            .collect();
        let e = Atlas::from_uv_set(&positions, &triangles, (0, &uvs), 16).unwrap_err();
        assert!(matches!(e, AtlasError::Overdrawn { page: 256, .. }), "{e}");
        assert!(e.to_string().contains("stack"), "{e}");
        // A few stacked triangles cost little: found as an overlap.
        let few = Atlas::from_uv_set(&positions[..6], &triangles[..2], (0, &uvs[..6]), 16);
        assert!(matches!(few, Err(AtlasError::Overlap { .. })), "{few:?}");
    }

    #[test]
    fn sizes_outside_the_range_are_refused() {
        let (positions, triangles) = cube();
        for (size, padding) in [(8, 2), (5000, 2), (32, 8)] {
            assert_eq!(
                Atlas::generate(&positions, &triangles, &AtlasOptions { size, padding }),
                Err(AtlasError::Size { size, padding })
            );
        }
        assert_eq!(
            Atlas::generate(&positions, &[[0, 0, 1]], &AtlasOptions::default()),
            Err(AtlasError::Empty)
        );
    }
}
