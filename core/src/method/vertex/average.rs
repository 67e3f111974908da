//! The static-average baseline: every vertex's mean AO over the reference
//! poses, the same in every pose. Pose-dependent methods must beat it.

use half::f16;

use crate::trace::AoBlock;
use aobake_runtime::method::vertex::form::{Block, LinearForm};

pub use aobake_runtime::method::vertex::average::StaticAverage;

/// The static average of `ao`: the mean over its rows.
pub fn fit(ao: &AoBlock) -> StaticAverage {
    StaticAverage {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_of_rows() {
        let ao = AoBlock {
            vertices: 2,
            values: vec![0.0, 1.0, 0.5, 0.5],
        };
        assert_eq!(fit(&ao).evaluate(), vec![0.25, 0.75]);
    }
}
