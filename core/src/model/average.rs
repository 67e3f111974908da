//! The static-average baseline: every vertex's mean AO over the reference
//! poses, the same in every pose. Pose-dependent methods must beat it.

use half::f16;

use super::form::{Block, LinearForm};
use crate::reference::AoBlock;

/// Mean AO per vertex.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticAverage {
    /// One block, one row: the means in f16.
    pub form: LinearForm,
}

impl StaticAverage {
    /// The mean over the rows of `ao`.
    pub fn fit(ao: &AoBlock) -> Self {
        let p = ao.poses().max(1) as f64;
        let mut sums = vec![0.0f64; ao.vertices];
        for r in 0..ao.poses() {
            for (s, &x) in sums.iter_mut().zip(ao.row(r)) {
                *s += f64::from(x);
            }
        }
        Self {
            form: LinearForm {
                vertices: ao.vertices,
                blocks: vec![Block {
                    rows: 1,
                    columns: ao.vertices,
                    coefficients: sums.iter().map(|&s| f16::from_f64(s / p)).collect(),
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
