//! The static-average baseline: every vertex's mean AO over the reference
//! poses, the same in every pose. Pose-dependent methods must beat it.

use half::f16;

use crate::trace::AoRows;
use aobake_runtime::method::vertex::form::{Block, LinearForm};

pub use aobake_runtime::method::vertex::average::StaticAverage;

/// The static average of `ao` (a block, or some of its rows read in
/// place): the mean over its rows.
pub fn fit<'a>(ao: impl Into<AoRows<'a>>) -> StaticAverage {
    let ao = ao.into();
    StaticAverage {
        form: LinearForm {
            vertices: ao.columns(),
            blocks: vec![Block {
                rows: 1,
                columns: ao.columns(),
                coefficients: ao.mean().into_iter().map(f16::from_f64).collect(),
                map: None,
            }],
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::AoBlock;

    #[test]
    fn mean_of_rows() {
        let ao = AoBlock {
            vertices: 2,
            values: vec![0.0, 1.0, 0.5, 0.5],
        };
        assert_eq!(fit(&ao).evaluate(), vec![0.25, 0.75]);
    }
}
