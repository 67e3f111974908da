//! Reference data: ground-truth AO of a character in a batch of poses, the
//! unit of work a bake's jobs compute (DESIGN §4–5). A batch depends only
//! on its poses and the tracing parameters, so batches can run on any
//! worker, in any order, and be stacked into the training matrix.

use super::{
    Progress, Scene, SceneOptions, SurfaceMesh, SurfaceParams, TraceError, vertex_occlusion,
    vertex_occlusion_many,
};
use crate::{Character, Pose};

/// Occlusion of every vertex in every pose of a batch: row `p` (pose `p`
/// of the batch) is `values[p * vertices..(p + 1) * vertices]`, in the
/// character's vertex order.
#[derive(Debug, Clone, PartialEq)]
pub struct AoBlock {
    /// Vertices per pose.
    pub vertices: usize,
    /// Pose-major occlusion values (0 = open, 1 = blocked).
    pub values: Vec<f32>,
}

impl AoBlock {
    /// The rows `rows`, in that order.
    pub fn select(&self, rows: impl IntoIterator<Item = usize>) -> Self {
        Self {
            vertices: self.vertices,
            values: rows
                .into_iter()
                .flat_map(|r| self.row(r).iter().copied())
                .collect(),
        }
    }

    /// [`AoBlock::select`] of only the columns `columns`: a block as wide
    /// as the range (what a fit a chunk of columns at a time copies, not
    /// the whole width).
    pub fn select_columns(
        &self,
        rows: impl IntoIterator<Item = usize>,
        columns: std::ops::Range<usize>,
    ) -> Self {
        Self {
            vertices: columns.len(),
            values: rows
                .into_iter()
                .flat_map(|r| self.row(r)[columns.clone()].iter().copied())
                .collect(),
        }
    }

    /// Number of poses.
    pub fn poses(&self) -> usize {
        self.values.len().checked_div(self.vertices).unwrap_or(0)
    }

    /// The occlusion of every vertex in pose `p`.
    pub fn row(&self, p: usize) -> &[f32] {
        &self.values[p * self.vertices..(p + 1) * self.vertices]
    }

    /// Each vertex's mean occlusion over the poses (zeros without poses).
    pub fn mean(&self) -> Vec<f64> {
        AoRows::all(self).mean()
    }
}

/// Some rows of an [`AoBlock`] read in place: what a fit to part of a
/// block (a fold of cross-validation, the reference rows it chose) reads
/// without copying it, as [`AoBlock::select`] would. The same values in
/// the same order, so a fit to a view gives the bits a fit to the copy
/// gives.
#[derive(Debug, Clone, Copy)]
pub struct AoRows<'a> {
    block: &'a AoBlock,
    /// The block's rows, in order (`None`: all of them).
    rows: Option<&'a [usize]>,
}

impl<'a> From<&'a AoBlock> for AoRows<'a> {
    fn from(block: &'a AoBlock) -> Self {
        Self::all(block)
    }
}

impl<'a> AoRows<'a> {
    /// Every row of `block`.
    pub fn all(block: &'a AoBlock) -> Self {
        Self { block, rows: None }
    }

    /// Rows `rows` of `block`, in that order.
    pub fn some(block: &'a AoBlock, rows: &'a [usize]) -> Self {
        Self {
            block,
            rows: Some(rows),
        }
    }

    /// The block the rows are of.
    pub fn block(&self) -> &'a AoBlock {
        self.block
    }

    /// Columns (vertices or texels) per row.
    pub fn columns(&self) -> usize {
        self.block.vertices
    }

    /// Rows in the view.
    pub fn poses(&self) -> usize {
        self.rows.map_or(self.block.poses(), <[usize]>::len)
    }

    /// The block's row of the view's row `i`.
    pub fn index(&self, i: usize) -> usize {
        self.rows.map_or(i, |rows| rows[i])
    }

    /// The view's row `i`.
    pub fn row(&self, i: usize) -> &'a [f32] {
        self.block.row(self.index(i))
    }

    /// The block's rows of the view's rows `positions`: a view of them is
    /// a view of this one's.
    pub fn rows_of(&self, positions: &[usize]) -> Vec<usize> {
        positions.iter().map(|&i| self.index(i)).collect()
    }

    /// The rows as a block of their own: borrowed when the view has
    /// every row, else copied (for a fit that needs one).
    pub fn to_block(&self) -> std::borrow::Cow<'a, AoBlock> {
        match self.rows {
            None => std::borrow::Cow::Borrowed(self.block),
            Some(rows) => std::borrow::Cow::Owned(self.block.select(rows.iter().copied())),
        }
    }

    /// Each column's mean over the rows, summed in the rows' order (zeros
    /// without rows).
    pub fn mean(&self) -> Vec<f64> {
        let mut sums = vec![0.0f64; self.columns()];
        for i in 0..self.poses() {
            for (s, &x) in sums.iter_mut().zip(self.row(i)) {
                *s += f64::from(x);
            }
        }
        let p = self.poses().max(1) as f64;
        sums.iter_mut().for_each(|s| *s /= p);
        sums
    }
}

/// Skins `character` into each pose, builds a fresh BVH (rebuilding beats
/// refitting: see `trace`'s notes) and traces per-vertex AO with `params`.
/// Every pose uses the same seed, so a vertex's rays take the same
/// directions relative to its normal in every pose: the sampling noise is
/// correlated across poses and the pose-to-pose differences, which the
/// models fit, are less noisy. `progress` counts vertices.
pub fn trace_poses(
    character: &Character,
    poses: &[Pose],
    options: &SceneOptions,
    params: &SurfaceParams,
    progress: Progress<'_>,
) -> Result<AoBlock, TraceError> {
    let vertices = character.positions.len();
    let mut values = Vec::with_capacity(vertices * poses.len());
    if super::engine::engine().is_some() {
        // One batch, so that a GPU traces every pose in one dispatch.
        use rayon::prelude::*;
        let posed: Vec<_> = poses.par_iter().map(|p| character.skin(p)).collect();
        let scenes = posed
            .par_iter()
            .map(|p| Scene::new(&p.positions, &character.triangles, options))
            .collect::<Result<Vec<_>, _>>()?;
        let meshes: Vec<SurfaceMesh<'_>> = posed
            .iter()
            .map(|p| SurfaceMesh {
                positions: &p.positions,
                normals: &p.normals,
                triangles: &character.triangles,
            })
            .collect();
        let scenes: Vec<&Scene> = scenes.iter().collect();
        for row in vertex_occlusion_many(&scenes, &meshes, params, progress)? {
            values.extend(row);
        }
        return Ok(AoBlock { vertices, values });
    }
    for pose in poses {
        values.extend(trace_pose(character, pose, options, params, progress)?.1);
    }
    Ok(AoBlock { vertices, values })
}

/// One pose of [`trace_poses`]: the posed scene (for callers that trace
/// more from it, such as a ground under the character) and the occlusion
/// of every vertex.
pub fn trace_pose(
    character: &Character,
    pose: &Pose,
    options: &SceneOptions,
    params: &SurfaceParams,
    progress: Progress<'_>,
) -> Result<(Scene, Vec<f32>), TraceError> {
    trace_posed(character, &character.skin(pose), options, params, progress)
}

/// [`trace_pose`] of a pose already skinned into `posed`, for callers
/// that trace more points on the same mesh (a texel atlas's).
pub fn trace_posed(
    character: &Character,
    posed: &crate::PosedMesh,
    options: &SceneOptions,
    params: &SurfaceParams,
    progress: Progress<'_>,
) -> Result<(Scene, Vec<f32>), TraceError> {
    let scene = Scene::new(&posed.positions, &character.triangles, options)?;
    let mesh = SurfaceMesh {
        positions: &posed.positions,
        normals: &posed.normals,
        triangles: &character.triangles,
    };
    let ao = vertex_occlusion(&scene, &mesh, params, progress)?;
    Ok((scene, ao))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Limits, Upload, import_character, trace::no_progress};

    #[test]
    fn batches_stack_into_the_whole() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/data/characters/RiggedFigure/RiggedFigure.glb"
        );
        let bytes = std::fs::read(path).unwrap();
        let imported = import_character(Upload::single(&bytes), &Limits::default()).unwrap();
        let c = &imported.character;
        let clip = &imported.clips[0];
        let poses: Vec<Pose> = [0.0, 0.4, 0.8, 1.2]
            .iter()
            .map(|&t| Pose::sample(&c.skeleton, clip, t))
            .collect();
        let params = SurfaceParams {
            samples: 32,
            max_distance: 1.0,
            seed: 4,
            falloff: crate::trace::Falloff::None,
        };
        let options = SceneOptions::default();
        let whole = trace_poses(c, &poses, &options, &params, &no_progress).unwrap();
        assert_eq!(whole.poses(), 4);
        assert_eq!(whole.vertices, c.positions.len());
        let first = trace_poses(c, &poses[..1], &options, &params, &no_progress).unwrap();
        let rest = trace_poses(c, &poses[1..], &options, &params, &no_progress).unwrap();
        assert_eq!(first.row(0), whole.row(0));
        assert_eq!([first.values, rest.values].concat(), whole.values);
        // The pose changes the occlusion.
        assert_ne!(whole.row(0), whole.row(2));
    }
}
