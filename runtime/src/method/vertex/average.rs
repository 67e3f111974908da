//! The static-average baseline: every vertex's mean AO over the reference
//! poses, the same in every pose. Pose-dependent methods must beat it.

use super::form::LinearForm;

/// Mean AO per vertex.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticAverage {
    /// One block, one row: the means in f16.
    pub form: LinearForm,
}

impl StaticAverage {
    /// The AO of every vertex, whatever the pose.
    pub fn evaluate(&self) -> Vec<f32> {
        self.form.evaluate(&[1.0])
    }
}
