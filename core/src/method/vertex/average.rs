//! The static-average baseline: every vertex's mean AO over the reference
//! poses, the same in every pose. Pose-dependent methods must beat it.

use half::f16;

use crate::trace::AoBlock;
use aobake_runtime::method::vertex::form::{Block, LinearForm};

/// Mean AO per vertex.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticAverage {
    /// One block, one row: the means in f16.
    pub form: LinearForm,
}

impl StaticAverage {
    /// The mean over the rows of `ao`.
    pub fn fit(ao: &AoBlock) -> Self {
        Self {
            form: LinearForm {
                vertices: ao.vertices,
                blocks: vec![Block {
                    rows: 1,
                    columns: ao.vertices,
                    coefficients: ao.mean().into_iter().map(f16::from_f64).collect(),
                    map: None,
                }],
            },
        }
    }

    /// The AO of every vertex, whatever the pose.
    pub fn evaluate(&self) -> Vec<f32> {
        self.form.evaluate(&[1.0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_of_rows() {
        let ao = AoBlock {
            vertices: 2,
            values: vec![0.0, 1.0, 0.5, 0.5],
        };
        assert_eq!(StaticAverage::fit(&ao).evaluate(), vec![0.25, 0.75]);
    }
}
