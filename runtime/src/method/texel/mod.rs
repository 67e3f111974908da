//! The texel methods as an engine reads them: a vertex method's model
//! whose columns are texels of a UV atlas instead of vertices, and the
//! atlas itself ([`AtlasLayout`]): the UV set to draw the character with,
//! and where each column's value goes in the textures. Per pose the
//! weights are the vertex method's ([`Model::weights`]); each texture is
//! one row of coefficients scattered into the atlas and dilated past the
//! charts' borders ([`AtlasLayout::image`]); per pixel the AO is the
//! weighted sum of the textures, bilinearly filtered ([`bilinear`]).
//! aobake-core generates atlases and fits the models.

use serde::{Deserialize, Serialize};

use crate::{
    Family, Method,
    container::{AssetError, AssetHeaderFields, Container, Data, Section},
    method::vertex::{AssetHeader, Model},
    rig::Skeleton,
};

/// Version of the texel methods' algorithms (the atlas, the texels and
/// the fit over them), part of the bake key.
pub const ALGORITHM_VERSION: u32 = 1;

/// What a texel asset's values mean, written into its header.
pub const UNITS: &str =
    "occlusion per texel (the ATTX section places each in the atlas): 0 = open, 1 = blocked";

/// The largest atlas side an asset may declare: core's largest (4096²
/// texels, 64 MB of f32 per texture), so that a hostile header cannot
/// make a reader allocate more.
const MAX_SIDE: u32 = 4096;

/// The atlas of a texel asset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AtlasLayout {
    /// Texels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Per atlas vertex, the character vertex (aobake's vertex order) it
    /// was made from: its position, normal and skin.
    pub xref: Vec<u32>,
    /// Per atlas vertex, its texture coordinate in `[0, 1]²`: `(0, 0)` is
    /// the outer corner of texel row 0, column 0, and `v` grows with the
    /// row (glTF's, wgpu's and Vulkan's convention).
    pub uvs: Vec<[f32; 2]>,
    /// The character's triangles in its order, corner for corner, over
    /// the atlas vertices.
    pub triangles: Vec<[u32; 3]>,
    /// Per model column, its texel: `row × width + column`.
    pub texels: Vec<u32>,
}

impl AtlasLayout {
    /// The `width × height` texture of per-column `values`: each at its
    /// texel, every other texel dilated from the charts ([`dilate`]).
    pub fn image(&self, values: &[f32]) -> Vec<f32> {
        texture(self.width, self.height, self.texels.iter().copied(), values)
    }

    /// Checks the layout against itself and `columns`, the model's.
    fn check(&self, columns: usize, vertices: Option<usize>) -> Result<(), AssetError> {
        let bad = |m: &str| AssetError::Malformed(format!("the atlas: {m}"));
        if !(1..=MAX_SIDE).contains(&self.width) || !(1..=MAX_SIDE).contains(&self.height) {
            return Err(bad("its size is 0 or absurdly large"));
        }
        let area = self.width as usize * self.height as usize;
        if self.texels.len() != columns {
            return Err(bad("it places a number of texels other than the model's"));
        }
        let mut seen = vec![false; area];
        for &t in &self.texels {
            let slot = seen
                .get_mut(t as usize)
                .ok_or_else(|| bad("a texel is outside it"))?;
            if std::mem::replace(slot, true) {
                return Err(bad("two columns share a texel"));
            }
        }
        if self.uvs.len() != self.xref.len() {
            return Err(bad("its vertices have other than one UV each"));
        }
        if self.uvs.iter().flatten().any(|x| !(0.0..=1.0).contains(x)) {
            return Err(bad("a UV is not a number in [0, 1]"));
        }
        let n = self.xref.len() as u32;
        if self.triangles.iter().flatten().any(|&i| i >= n) {
            return Err(bad("a triangle names a vertex it does not have"));
        }
        if let Some(v) = vertices
            && self.xref.iter().any(|&x| x as usize >= v)
        {
            return Err(bad("a vertex comes from one the character does not have"));
        }
        Ok(())
    }
}

/// A texel method's model: the vertex method's model over the atlas's
/// texels.
#[derive(Debug, Clone, PartialEq)]
pub struct TexelModel {
    /// The method.
    pub method: Method,
    /// The model; its columns are [`AtlasLayout::texels`].
    pub model: Model,
    /// The atlas.
    pub atlas: AtlasLayout,
}

impl TexelModel {
    /// The asset: the model's header and sections under the texel
    /// method's name, and the atlas's sections (`ATSZ` width and height,
    /// `ATXR` vertex sources, `ATUV` UVs, `ATTR` triangles, `ATTX` texels).
    pub fn to_container(&self, header: AssetHeaderFields, skeleton: &Skeleton) -> Container {
        let mut c = self
            .model
            .to_container_as(self.method, UNITS, header, skeleton);
        let a = &self.atlas;
        let section = |tag: &[u8; 4], data| Section { tag: *tag, data };
        c.sections.extend([
            section(b"ATSZ", Data::U32(vec![a.width, a.height])),
            section(b"ATXR", Data::U32(a.xref.clone())),
            section(
                b"ATUV",
                Data::F32(a.uvs.iter().flatten().copied().collect()),
            ),
            section(
                b"ATTR",
                Data::U32(a.triangles.iter().flatten().copied().collect()),
            ),
            section(b"ATTX", Data::U32(a.texels.clone())),
        ]);
        c
    }

    /// Reads a texel asset back, checking the atlas against the model
    /// (and against a character of `vertices` vertices, when given).
    pub fn from_container(
        container: &Container,
        vertices: Option<usize>,
    ) -> Result<(Self, AssetHeader), AssetError> {
        let (model, header) = Model::from_container_of(container, Family::Texel)?;
        // texel-linear's model is vertex-linear's (its static average
        // too); no other layout is one, and its joints go unchecked.
        if !matches!(model, Model::VertexLinear(..) | Model::StaticAverage(_)) {
            return Err(AssetError::Malformed(
                "a texel asset holds a vertex-linear model, not this layout".into(),
            ));
        }
        let u32s = |tag: &[u8; 4]| match container.section(tag)? {
            Data::U32(v) => Ok(v.clone()),
            _ => Err(AssetError::Malformed(format!(
                "{} must be u32",
                String::from_utf8_lossy(tag)
            ))),
        };
        let size = u32s(b"ATSZ")?;
        let [width, height] = size[..] else {
            return Err(AssetError::Malformed(
                "ATSZ must hold the width and the height".into(),
            ));
        };
        let Data::F32(uvs) = container.section(b"ATUV")? else {
            return Err(AssetError::Malformed("ATUV must be f32".into()));
        };
        let triangles = u32s(b"ATTR")?;
        if uvs.len() % 2 != 0 || triangles.len() % 3 != 0 {
            return Err(AssetError::Malformed(
                "ATUV must hold pairs and ATTR triples".into(),
            ));
        }
        let atlas = AtlasLayout {
            width,
            height,
            xref: u32s(b"ATXR")?,
            uvs: uvs.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
            triangles: triangles
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
            texels: u32s(b"ATTX")?,
        };
        atlas.check(model.vertices(), vertices)?;
        Ok((
            Self {
                method: container.method,
                model,
                atlas,
            },
            header,
        ))
    }
}

/// Why a texel model has no basis textures.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BasisError {
    /// Its coefficients are sparse (a vertex-linear fit with a
    /// threshold): rows with holes, not textures.
    #[error("a sparse texel model has no basis textures (bake with linear.threshold 0)")]
    Sparse,
    /// A block's columns are clusters of texels, not texels.
    #[error("a texel model with clustered columns has no basis textures")]
    Clustered,
    /// More texture values than a reader should allocate.
    #[error(
        "{layers} textures of {width} × {height} texels are more than the {max} values a reader allocates"
    )]
    TooLarge {
        /// Textures (weights).
        layers: usize,
        /// Texels per row.
        width: u32,
        /// Rows.
        height: u32,
        /// The most values allowed.
        max: u64,
    },
}

/// The most textures (weights) a texel model may have: one layer each of
/// an array texture, and 256 layers is what every GPU holds (WebGPU's and
/// WebGL2's least `maxTextureArrayLayers`; `TEXEL_MAX_LAYERS` in
/// `shaders/wgsl/common/texel_ao.wgsl`). texel-linear's `linear.basis` is
/// kept below it.
pub const MAX_TEXTURES: usize = 256;

/// The most values [`TexelModel::basis`] makes (4 GB of f32): 64 textures
/// of 4096² fit; a hostile header cannot ask for hundreds of GB.
pub const MAX_BASIS_VALUES: u64 = 1 << 30;

impl TexelModel {
    /// A pose's texture before the clamp: `Σ_k w_k · basis_k` per texel
    /// of the atlas, dilated, row-major; per pixel
    /// `ao = clamp(bilinear(texture, uv), 0, 1)`, what the shader computes
    /// from the basis textures (filtering is linear).
    pub fn texture(&self, weights: &[f32]) -> Result<Vec<f32>, BasisError> {
        let crate::method::vertex::FormRef::Dense(form) = self.model.form() else {
            return Err(BasisError::Sparse);
        };
        if form.blocks.iter().any(|b| b.map.is_some()) {
            return Err(BasisError::Clustered);
        }
        let mut sums = vec![0.0; form.vertices];
        form.sum_into(weights, &mut sums);
        Ok(self.atlas.image(&sums))
    }

    /// The basis textures an engine samples, one per weight in weight
    /// order: coefficient row k scattered into the atlas and dilated
    /// ([`AtlasLayout::image`]), `width × height` row-major. Per pixel
    /// `ao = clamp(Σ_k w_k · basis_k(uv), 0, 1)` with the pose's weights
    /// ([`Model::weights`]), bilinear filtering commuting with the sum.
    pub fn basis(&self) -> Result<Vec<Vec<f32>>, BasisError> {
        let crate::method::vertex::FormRef::Dense(form) = self.model.form() else {
            return Err(BasisError::Sparse);
        };
        let a = &self.atlas;
        let layers = form.weight_count();
        if layers as u64 * u64::from(a.width) * u64::from(a.height) > MAX_BASIS_VALUES {
            return Err(BasisError::TooLarge {
                layers,
                width: a.width,
                height: a.height,
                max: MAX_BASIS_VALUES,
            });
        }
        if form.blocks.iter().any(|b| b.map.is_some()) {
            return Err(BasisError::Clustered);
        }
        Ok(form
            .blocks
            .iter()
            .flat_map(|b| b.coefficients.chunks_exact(b.columns.max(1)))
            .map(|row| a.image(&row.iter().map(|c| c.to_f32()).collect::<Vec<f32>>()))
            .collect())
    }
}

/// The `width × height` texture with `values[i]` at texel `texels[i]`
/// (`row × width + column`) and every other texel dilated from them
/// ([`dilate`]).
pub fn texture(
    width: u32,
    height: u32,
    texels: impl IntoIterator<Item = u32>,
    values: &[f32],
) -> Vec<f32> {
    let n = width as usize * height as usize;
    let mut image = vec![0.0; n];
    let mut filled = vec![false; n];
    for (t, &v) in texels.into_iter().zip(values) {
        image[t as usize] = v;
        filled[t as usize] = true;
    }
    dilate(&mut image, &mut filled, width, height);
    image
}

/// Fills every unfilled texel from its filled neighbours, ring by ring
/// outwards from the charts: each takes the mean of its filled
/// 8-neighbours of the previous ring, until every texel is filled (a mip
/// chain of any depth then averages chart values only). Deterministic.
pub fn dilate(image: &mut [f32], filled: &mut [bool], width: u32, height: u32) {
    let (w, h) = (width as usize, height as usize);
    let neighbours = |i: usize| {
        let (x, y) = (i % w, i / w);
        (y.saturating_sub(1)..=(y + 1).min(h - 1)).flat_map(move |ny| {
            (x.saturating_sub(1)..=(x + 1).min(w - 1)).map(move |nx| ny * w + nx)
        })
    };
    // The ring to fill next: the unfilled neighbours of the last ring (at
    // first, of every filled texel), each once, in row-major order. Each
    // ring costs its own size, not the image's.
    let mut last: Vec<usize> = (0..w * h).filter(|&i| filled[i]).collect();
    let mut queued = vec![false; w * h];
    let mut ring: Vec<(usize, f32)> = Vec::new();
    while !last.is_empty() {
        let mut next: Vec<usize> = Vec::new();
        for &i in &last {
            for n in neighbours(i) {
                if !filled[n] && !std::mem::replace(&mut queued[n], true) {
                    next.push(n);
                }
            }
        }
        next.sort_unstable();
        ring.clear();
        for &i in &next {
            let (mut sum, mut count) = (0.0f32, 0u32);
            for n in neighbours(i) {
                if filled[n] {
                    sum += image[n];
                    count += 1;
                }
            }
            ring.push((i, sum / count as f32));
        }
        for &(i, v) in &ring {
            image[i] = v;
            filled[i] = true;
        }
        last = next;
    }
}

/// Bilinear filtering of a `width × height` image at texture coordinate
/// `uv` with clamp-to-edge addressing: what a GPU's linear sampler
/// returns (texel centres at half-integers).
pub fn bilinear(image: &[f32], width: u32, height: u32, uv: [f32; 2]) -> f32 {
    let (w, h) = (i64::from(width), i64::from(height));
    let x = uv[0] * width as f32 - 0.5;
    let y = uv[1] * height as f32 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |xi: i64, yi: i64| {
        let xi = xi.clamp(0, w - 1) as usize;
        let yi = yi.clamp(0, h - 1) as usize;
        image[yi * width as usize + xi]
    };
    let (x0, y0) = (x0 as i64, y0 as i64);
    let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx;
    let bottom = at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx;
    top * (1.0 - fy) + bottom * fy
}

#[cfg(test)]
mod tests {
    use half::f16;

    use super::*;
    use crate::method::vertex::{Block, LinearForm, StaticAverage};

    /// A static average over three texels of a 4 × 2 atlas of one
    /// triangle.
    fn asset() -> TexelModel {
        TexelModel {
            method: Method::TexelLinear,
            model: Model::StaticAverage(StaticAverage {
                form: LinearForm {
                    vertices: 3,
                    blocks: vec![Block {
                        rows: 1,
                        columns: 3,
                        coefficients: [0.25, 0.5, 1.0].map(f16::from_f32).to_vec(),
                        map: None,
                    }],
                },
            }),
            atlas: AtlasLayout {
                width: 4,
                height: 2,
                xref: vec![0, 1, 2],
                uvs: vec![[0.1, 0.1], [0.9, 0.1], [0.1, 0.9]],
                triangles: vec![[0, 1, 2]],
                texels: vec![0, 1, 4],
            },
        }
    }

    fn round_trip(edit: impl FnOnce(&mut Container)) -> Result<TexelModel, AssetError> {
        let skeleton = Skeleton {
            nodes: Vec::new(),
            order: Vec::new(),
        };
        let mut c = asset().to_container(AssetHeaderFields::for_tests(), &skeleton);
        edit(&mut c);
        let c = Container::from_bytes(&c.to_bytes())?;
        TexelModel::from_container(&c, Some(3)).map(|(m, _)| m)
    }

    fn set(c: &mut Container, tag: &[u8; 4], data: Data) {
        c.sections.iter_mut().find(|s| &s.tag == tag).unwrap().data = data;
    }

    #[test]
    fn a_texel_asset_round_trips_and_its_texture_is_dilated() {
        let back = round_trip(|_| {}).unwrap();
        assert_eq!(back, asset());
        // The values at their texels; the others from their neighbours.
        let image = back.atlas.image(&[0.25, 0.5, 1.0]);
        assert_eq!((image[0], image[1], image[4]), (0.25, 0.5, 1.0));
        assert!(image.iter().all(|v| (0.25..=1.0).contains(v)));
        // Texel (0, 0)'s centre reads its value.
        assert_eq!(bilinear(&image, 4, 2, [0.125, 0.25]), 0.25);
    }

    #[test]
    fn a_hostile_atlas_is_refused_not_followed() {
        let refused = |edit: &dyn Fn(&mut Container)| {
            round_trip(|c| edit(c)).expect_err("a broken atlas must be refused")
        };
        // A page no atlas has: refused before anything is allocated for it.
        refused(&|c| set(c, b"ATSZ", Data::U32(vec![1 << 20, 1 << 20])));
        refused(&|c| set(c, b"ATSZ", Data::U32(vec![4])));
        // Columns outside the page, or two on one texel.
        refused(&|c| set(c, b"ATTX", Data::U32(vec![0, 1, 8])));
        refused(&|c| set(c, b"ATTX", Data::U32(vec![0, 1, 1])));
        refused(&|c| set(c, b"ATTX", Data::U32(vec![0, 1])));
        // A triangle over a vertex it does not have; a vertex from one
        // the character does not have; a UV that is not a number.
        refused(&|c| set(c, b"ATTR", Data::U32(vec![0, 1, 3])));
        refused(&|c| set(c, b"ATXR", Data::U32(vec![0, 1, 3])));
        refused(&|c| {
            set(
                c,
                b"ATUV",
                Data::F32(vec![0.1, 0.1, 0.9, 0.1, f32::NAN, 0.9]),
            )
        });
        refused(&|c| set(c, b"ATUV", Data::F32(vec![0.1, 0.1, 0.9])));
        refused(&|c| set(c, b"ATUV", Data::F32(vec![0.1, 0.1, 0.9, 0.1, 1e30, 0.9])));
        // A vertex asset is not a texel asset.
        refused(&|c| c.method = Method::VertexLinear);
    }
}
