//! The run-time form every vertex method reduces to (DESIGN §5): per pose,
//! a short vector of weights computed once on the CPU, then per vertex a
//! dot product of those weights with the vertex's f16 coefficients.
//!
//! ```text
//! ao[v] = Σ_b Σ_k w_b[k] · C_b[k, col_b(v)]      col_b(v) = map_b[v], or v
//! ```
//!
//! * static average: one block, one row (the mean), `w = [1]`;
//! * vertex-linear: one block of N+1 rows, `w = [joint angles…, 1]`
//!   (or the same as a sparse matrix, [`SparseForm`]);
//! * vertex-clustered: a block for the mean AO (`w = [1]`) and one block
//!   per pose cluster with `w = ω_j · P_j (h − h̄_j)` (Kirk & Arikan Eq. 4),
//!   whose columns are vertex clusters when spatial compression is on.
//!
//! The sum is clamped to [0, 1], the range of AO, as a renderer would
//! saturate it: a linear model can overshoot on poses far from its
//! training set.
//!
//! `shaders/wgsl/vertex_ao.wgsl` (and `vertex_ao_vs.wgsl`, in a vertex
//! shader) evaluates exactly this layout on the GPU.

use half::f16;

use crate::method::{TooLarge, to_u32};

/// One block of coefficients: `rows × columns`, row-major, so that for a
/// given row neighbouring vertices read neighbouring values.
#[derive(Debug, Clone, PartialEq)]
pub struct Block {
    /// Weights this block takes.
    pub rows: usize,
    /// Coefficient columns: vertices, or vertex clusters with a map.
    pub columns: usize,
    /// `rows × columns` values, row-major.
    pub coefficients: Vec<f16>,
    /// Column of each vertex, when columns are vertex clusters.
    pub map: Option<Vec<u32>>,
}

/// A dense linear form over the vertices: blocks of coefficients.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearForm {
    /// Vertices.
    pub vertices: usize,
    /// The blocks, in weight order.
    pub blocks: Vec<Block>,
}

impl LinearForm {
    /// Weights per pose: the sum of the blocks' rows.
    pub fn weight_count(&self) -> usize {
        self.blocks.iter().map(|b| b.rows).sum()
    }

    /// AO of every vertex for one pose's weights.
    pub fn evaluate(&self, weights: &[f32]) -> Vec<f32> {
        let mut out = vec![0.0f32; self.vertices];
        self.evaluate_into(weights, &mut out);
        out
    }

    /// [`LinearForm::evaluate`] into `out`, one value per vertex, without
    /// allocating.
    pub fn evaluate_into(&self, weights: &[f32], out: &mut [f32]) {
        self.sum_into(weights, out);
        out.iter_mut().for_each(|x| *x = x.clamp(0.0, 1.0));
    }

    /// The weighted sum per vertex before [`LinearForm::evaluate`]'s
    /// clamp, into `out`: what a texel method's textures hold, since its
    /// shader clamps after filtering.
    pub fn sum_into(&self, weights: &[f32], out: &mut [f32]) {
        assert_eq!(weights.len(), self.weight_count(), "one weight per row");
        assert_eq!(out.len(), self.vertices, "one value per vertex");
        out.fill(0.0);
        let mut w = weights;
        for block in &self.blocks {
            let (mine, rest) = w.split_at(block.rows);
            w = rest;
            for (k, &wk) in mine.iter().enumerate() {
                if wk == 0.0 {
                    continue;
                }
                let row = &block.coefficients[k * block.columns..(k + 1) * block.columns];
                match &block.map {
                    None => out
                        .iter_mut()
                        .zip(row)
                        .for_each(|(o, c)| *o += wk * c.to_f32()),
                    Some(map) => out
                        .iter_mut()
                        .zip(map)
                        .for_each(|(o, &c)| *o += wk * row[c as usize].to_f32()),
                }
            }
        }
    }

    /// Coefficient and map bytes (f16 values, u16 or u32 map entries).
    pub fn bytes(&self) -> usize {
        self.blocks
            .iter()
            .map(|b| {
                2 * b.coefficients.len()
                    + b.map
                        .as_ref()
                        .map_or(0, |m| m.len() * map_entry_bytes(b.columns))
            })
            .sum()
    }
}

/// Bytes per vertex-cluster map entry in an asset: u16 when the columns
/// fit.
pub fn map_entry_bytes(columns: usize) -> usize {
    if columns <= usize::from(u16::MAX) + 1 {
        2
    } else {
        4
    }
}

/// A sparse `rows × vertices` form stored per vertex (CSR): the
/// vertex-linear model with small coefficients dropped.
#[derive(Debug, Clone, PartialEq)]
pub struct SparseForm {
    /// Vertices.
    pub vertices: usize,
    /// Weights per pose.
    pub rows: usize,
    /// `vertices + 1` offsets into `rows_of` and `values`.
    pub offsets: Vec<u32>,
    /// Row (weight index) of each kept coefficient.
    pub rows_of: Vec<u16>,
    /// Kept coefficients.
    pub values: Vec<f16>,
}

impl SparseForm {
    /// Keeps the coefficients of a dense one-block form whose magnitude
    /// reaches `threshold`, and always the rows listed in `keep_rows`.
    pub fn from_dense(block: &Block, vertices: usize, threshold: f32, keep_rows: &[usize]) -> Self {
        let mut offsets = Vec::with_capacity(vertices + 1);
        let (mut rows_of, mut values) = (Vec::new(), Vec::new());
        offsets.push(0);
        for v in 0..vertices {
            for k in 0..block.rows {
                let c = block.coefficients[k * block.columns + v];
                if c.to_f32().abs() >= threshold || keep_rows.contains(&k) {
                    rows_of.push(u16::try_from(k).expect("at most 65536 rows"));
                    values.push(c);
                }
            }
            offsets.push(u32::try_from(values.len()).expect("fits u32"));
        }
        Self {
            vertices,
            rows: block.rows,
            offsets,
            rows_of,
            values,
        }
    }

    /// AO of every vertex for one pose's weights.
    pub fn evaluate(&self, weights: &[f32]) -> Vec<f32> {
        let mut out = vec![0.0f32; self.vertices];
        self.evaluate_into(weights, &mut out);
        out
    }

    /// [`SparseForm::evaluate`] into `out`, one value per vertex, without
    /// allocating.
    pub fn evaluate_into(&self, weights: &[f32], out: &mut [f32]) {
        assert_eq!(weights.len(), self.rows, "one weight per row");
        assert_eq!(out.len(), self.vertices, "one value per vertex");
        for (o, w) in out.iter_mut().zip(self.offsets.windows(2)) {
            let r = w[0] as usize..w[1] as usize;
            *o = self.rows_of[r.clone()]
                .iter()
                .zip(&self.values[r])
                .map(|(&k, c)| weights[usize::from(k)] * c.to_f32())
                .sum::<f32>()
                .clamp(0.0, 1.0);
        }
    }

    /// Offsets, row indices and values.
    pub fn bytes(&self) -> usize {
        4 * self.offsets.len() + 2 * self.rows_of.len() + 2 * self.values.len()
    }

    /// Stored coefficients per vertex: its multiply-adds.
    pub fn multiply_adds(&self) -> f64 {
        self.values.len() as f64 / self.vertices.max(1) as f64
    }
}

/// Stored coefficients: a dense form, or a sparse one (vertex-linear with
/// small coefficients dropped, or an eigen-AO basis with small entries
/// dropped).
#[derive(Debug, Clone, PartialEq)]
pub enum Coefficients {
    /// All coefficients.
    Dense(LinearForm),
    /// The coefficients kept, per vertex.
    Sparse(SparseForm),
}

/// A model's coefficients, borrowed.
#[derive(Debug, Clone, Copy)]
pub enum FormRef<'a> {
    /// Blocks of dense coefficients.
    Dense(&'a LinearForm),
    /// Sparse coefficients per vertex.
    Sparse(&'a SparseForm),
}

impl FormRef<'_> {
    /// Vertices.
    pub fn vertices(self) -> usize {
        match self {
            Self::Dense(f) => f.vertices,
            Self::Sparse(s) => s.vertices,
        }
    }

    /// Weights per pose.
    pub fn weight_count(self) -> usize {
        match self {
            Self::Dense(f) => f.weight_count(),
            Self::Sparse(s) => s.rows,
        }
    }

    /// AO of every vertex for one pose's weights.
    pub fn evaluate(self, weights: &[f32]) -> Vec<f32> {
        let mut out = vec![0.0f32; self.vertices()];
        self.evaluate_into(weights, &mut out);
        out
    }

    /// AO of every vertex for one pose's weights, into `out` (one value
    /// per vertex) without allocating.
    pub fn evaluate_into(self, weights: &[f32], out: &mut [f32]) {
        match self {
            Self::Dense(f) => f.evaluate_into(weights, out),
            Self::Sparse(s) => s.evaluate_into(weights, out),
        }
    }
}

impl Coefficients {
    /// Borrowed.
    pub fn as_ref(&self) -> FormRef<'_> {
        match self {
            Self::Dense(f) => FormRef::Dense(f),
            Self::Sparse(s) => FormRef::Sparse(s),
        }
    }

    /// Vertices.
    pub fn vertices(&self) -> usize {
        self.as_ref().vertices()
    }

    /// AO of every vertex for one pose's weights.
    pub fn evaluate(&self, weights: &[f32]) -> Vec<f32> {
        self.as_ref().evaluate(weights)
    }

    /// Bytes of the coefficients (and maps or offsets).
    pub fn bytes(&self) -> usize {
        match self {
            Self::Dense(f) => f.bytes(),
            Self::Sparse(s) => s.bytes(),
        }
    }
}

/// Words per block in [`GpuArrays::blocks`]: rows, columns, coefficient
/// offset (in f16 elements), map offset (or [`GpuArrays::NO_MAP`]),
/// weight offset, and three words of padding (`BlockInfo` of
/// `shaders/wgsl/vertex_ao.wgsl`).
pub const BLOCK_WORDS: usize = 8;

/// A form's arrays as the GPU evaluators read them
/// (`shaders/wgsl/vertex_ao.wgsl` from storage buffers,
/// `vertex_ao_vs.wgsl` from R32Uint textures): what an engine uploads once
/// per asset. Every array holds at least one word (WebGPU and WebGL refuse
/// empty buffers and textures).
#[derive(Debug, Clone, PartialEq)]
pub struct GpuArrays {
    /// Sparse (CSR) coefficients (`cs_sparse`); else dense blocks
    /// (`cs_main`).
    pub sparse: bool,
    /// Vertices.
    pub vertices: u32,
    /// Weights per pose.
    pub weights: usize,
    /// Dense: [`BLOCK_WORDS`] words per block; sparse: empty.
    pub blocks: Vec<[u32; BLOCK_WORDS]>,
    /// f16 bits, two per word (element 2i in the low half).
    pub coefficients: Vec<u32>,
    /// Dense: the blocks' vertex-cluster maps, one after another; sparse:
    /// the `vertices + 1` row offsets.
    pub maps: Vec<u32>,
    /// Sparse: each coefficient's row, u16 two per word.
    pub sparse_rows: Vec<u32>,
}

/// Packs 16-bit values two per u32 (element 2i in the low half), padded
/// to at least one word.
fn pack16(values: impl ExactSizeIterator<Item = u16>) -> Vec<u32> {
    let mut out = vec![0u32; values.len().div_ceil(2).max(1)];
    for (i, v) in values.enumerate() {
        out[i / 2] |= u32::from(v) << (16 * (i % 2));
    }
    out
}

fn non_empty(mut v: Vec<u32>) -> Vec<u32> {
    if v.is_empty() {
        v.push(0);
    }
    v
}

impl GpuArrays {
    /// `map_offset` of a block whose columns are the vertices.
    pub const NO_MAP: u32 = u32::MAX;

    /// The arrays of `form`.
    pub fn new(form: FormRef<'_>) -> Result<Self, TooLarge> {
        match form {
            FormRef::Dense(form) => Self::dense(form),
            FormRef::Sparse(form) => Ok(Self {
                sparse: true,
                vertices: to_u32(form.vertices, "vertices")?,
                weights: form.rows,
                blocks: Vec::new(),
                coefficients: pack16(form.values.iter().map(|c| c.to_bits())),
                maps: non_empty(form.offsets.clone()),
                sparse_rows: pack16(form.rows_of.iter().copied()),
            }),
        }
    }

    fn dense(form: &LinearForm) -> Result<Self, TooLarge> {
        let mut blocks = Vec::with_capacity(form.blocks.len());
        let (mut coef_offset, mut weight_offset) = (0usize, 0usize);
        let mut maps = Vec::new();
        for b in &form.blocks {
            let map_offset = match &b.map {
                Some(m) => {
                    let at = to_u32(maps.len(), "map entries")?;
                    maps.extend_from_slice(m);
                    at
                }
                None => Self::NO_MAP,
            };
            blocks.push([
                to_u32(b.rows, "rows")?,
                to_u32(b.columns, "columns")?,
                to_u32(coef_offset, "coefficients")?,
                map_offset,
                to_u32(weight_offset, "weights")?,
                0,
                0,
                0,
            ]);
            coef_offset += b.coefficients.len();
            weight_offset += b.rows;
        }
        to_u32(coef_offset, "coefficients")?;
        let bits = form
            .blocks
            .iter()
            .flat_map(|b| b.coefficients.iter().map(|c| c.to_bits()));
        let coefficients = pack16(bits.collect::<Vec<_>>().into_iter());
        Ok(Self {
            sparse: false,
            vertices: to_u32(form.vertices, "vertices")?,
            weights: weight_offset,
            blocks,
            coefficients,
            maps: non_empty(maps),
            sparse_rows: vec![0],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn h(v: &[f32]) -> Vec<f16> {
        v.iter().map(|&x| f16::from_f32(x)).collect()
    }

    #[test]
    fn blocks_maps_and_sparse_agree_with_hand_sums() {
        let form = LinearForm {
            vertices: 3,
            blocks: vec![
                Block {
                    rows: 1,
                    columns: 3,
                    coefficients: h(&[0.5, 0.25, 0.0]),
                    map: None,
                },
                Block {
                    rows: 2,
                    columns: 2,
                    coefficients: h(&[1.0, -1.0, 0.5, 2.0]),
                    map: Some(vec![1, 0, 1]),
                },
            ],
        };
        let ao = form.evaluate(&[1.0, 0.1, 0.2]);
        assert_eq!(
            form.evaluate(&[1.0, 10.0, 0.0]),
            vec![0.0, 1.0, 0.0],
            "clamped"
        );
        // v0: 0.5 + 0.1·(−1) + 0.2·2; v1: 0.25 + 0.1·1 + 0.2·0.5; v2: 0 + 0.1·(−1) + 0.2·2
        let want = [0.8, 0.45, 0.3];
        for (a, b) in ao.iter().zip(want) {
            assert!((a - b).abs() < 1e-6, "{ao:?}");
        }
        assert_eq!(form.weight_count(), 3);
        assert_eq!(form.bytes(), 2 * 3 + 2 * 4 + 2 * 3);

        let dense = Block {
            rows: 3,
            columns: 2,
            coefficients: h(&[0.001, 0.5, -0.25, 0.002, 0.3, 0.4]),
            map: None,
        };
        let sparse = SparseForm::from_dense(&dense, 2, 0.01, &[2]);
        assert_eq!(sparse.offsets, vec![0, 2, 4]);
        assert_eq!(sparse.rows_of, vec![1, 2, 0, 2]);
        let w = [2.0, 1.0, 1.0];
        let s = sparse.evaluate(&w);
        // v0 = −0.25·1 + 0.3·1; v1 = 0.5·2 + 0.4·1 = 1.4, clamped to 1.
        assert!((s[0] - 0.05).abs() < 1e-3, "{s:?}");
        assert_eq!(s[1], 1.0, "clamped");
    }
}
