//! The raw field of one cube face, as a `face` job builds it and the
//! encodings read it, and the pieces its checkpoints are made of.
//!
//! * [`FaceField`]: occlusion at every texel, shell and time sample of a
//!   face, one byte each (`round(255 · v)`: a step of 0.004, below both
//!   the ray noise at the default 64 rays and the encodings' own
//!   coefficient steps), texel-major (`[texel][shell][time]`) so that each
//!   texel's (shell × time) block is contiguous for the encoders. At the
//!   defaults (128², 8 shells, 255 times) that is 33 MiB; a batch being
//!   traced (8 time samples, 1M points) holds about as much again in its
//!   tallies, and the next batch's meshes (built meanwhile) are small.
//! * [`Part`]: the slices of a run of consecutive time samples, as
//!   computed (`[time][shell][texel]`). A checkpoint stores only the parts
//!   made since the one before, as blobs, and a small [`Manifest`] listing
//!   every part's digest; a new attempt fetches the parts and goes on at
//!   the first missing time sample. Parts are content-addressed and the
//!   slices are a pure function of (seed, face, time), so the field, and
//!   the asset, do not depend on where the job was interrupted.

use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::trace::{KroonParams, TraceError};

use super::{
    field::{face_points, face_scenes, trace_face},
    geometry::Spheroid,
};

/// One face's field.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FaceField {
    /// Texels per face edge.
    pub resolution: usize,
    /// Shells.
    pub shells: usize,
    /// Time samples.
    pub times: usize,
    /// `resolution² × shells × times` bytes, texel-major.
    pub values: Vec<u8>,
}

/// Occlusion in [0, 1] as a field byte.
pub fn quantise(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// A field byte as occlusion.
pub fn dequantise(b: u8) -> f32 {
    f32::from(b) / 255.0
}

/// Time samples per checkpoint: about 32 checkpoints a face whatever
/// `S_t` is (8 time samples, about 1 MiB, at the defaults).
pub fn checkpoint_batch(times: usize) -> usize {
    times.div_ceil(32).max(1)
}

impl FaceField {
    /// An all-zero field.
    pub fn new(resolution: usize, shells: usize, times: usize) -> Self {
        Self {
            resolution,
            shells,
            times,
            values: vec![0; resolution * resolution * shells * times],
        }
    }

    /// Points per time slice (shells × texels).
    pub fn slice_len(&self) -> usize {
        self.shells * self.resolution * self.resolution
    }

    /// Stores consecutive time samples from `first` on: `slices` holds
    /// whole slices (`[shell][texel]` bytes each, the order of
    /// `field::face_points`), one after another. Each texel's block is
    /// written by one thread, a run of time samples at a time.
    pub fn insert(&mut self, first: usize, slices: &[u8]) {
        let texels = self.resolution * self.resolution;
        let n = self.slice_len();
        debug_assert_eq!(slices.len() % n.max(1), 0);
        let count = slices.len() / n.max(1);
        let (shells, times) = (self.shells, self.times);
        debug_assert!(first + count <= times);
        self.values
            .par_chunks_mut(shells * times)
            .enumerate()
            .for_each(|(t, block)| {
                for (k, row) in block.chunks_exact_mut(times).enumerate() {
                    let column = k * texels + t;
                    for (i, v) in row[first..first + count].iter_mut().enumerate() {
                        *v = slices[i * n + column];
                    }
                }
            });
    }

    /// Texel `t`'s (shell × time) block, shell-major.
    pub fn texel(&self, t: usize) -> &[u8] {
        let n = self.shells * self.times;
        &self.values[t * n..(t + 1) * n]
    }

    /// The field as a blob: `AOFF`, format 1, resolution, shells, times
    /// (u32 each), then the bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(20 + self.values.len());
        out.extend(FIELD_MAGIC);
        for v in [1, self.resolution, self.shells, self.times] {
            out.extend((v as u32).to_le_bytes());
        }
        out.extend(&self.values);
        out
    }

    /// Reads a blob back, checking it against the expected shape.
    pub fn from_bytes(bytes: &[u8], shape: (usize, usize, usize)) -> Result<Self, String> {
        let head = read_head(bytes, FIELD_MAGIC, 20)?;
        if (head[1], head[2], head[3]) != shape || head[0] != 1 {
            return Err("a face field has another shape than the bake's".into());
        }
        let (resolution, shells, times) = shape;
        let values = bytes[20..].to_vec();
        if values.len() != resolution * resolution * shells * times {
            return Err("a face field's length does not match its header".into());
        }
        Ok(Self {
            resolution,
            shells,
            times,
            values,
        })
    }
}

const FIELD_MAGIC: &[u8; 4] = b"AOFF";
const PART_MAGIC: &[u8; 4] = b"AOFP";

fn read_head(bytes: &[u8], magic: &[u8; 4], len: usize) -> Result<[usize; 4], String> {
    if bytes.len() < len || &bytes[..4] != magic {
        return Err(format!(
            "not a {} blob",
            String::from_utf8_lossy(&magic[..])
        ));
    }
    Ok(std::array::from_fn(|i| {
        u32::from_le_bytes(bytes[4 + 4 * i..8 + 4 * i].try_into().expect("4 bytes")) as usize
    }))
}

/// Consecutive time slices of one face.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Part {
    /// The first time sample.
    pub first: usize,
    /// Slices of `slice_len` bytes each.
    pub slices: Vec<u8>,
}

impl Part {
    /// As a blob: `AOFP`, format 1, face, first time, slices (u32 each),
    /// then the bytes.
    pub fn to_bytes(&self, face: usize, slice_len: usize) -> Vec<u8> {
        let mut out = Vec::with_capacity(20 + self.slices.len());
        out.extend(PART_MAGIC);
        for v in [1, face, self.first, self.slices.len() / slice_len.max(1)] {
            out.extend((v as u32).to_le_bytes());
        }
        out.extend(&self.slices);
        out
    }

    /// Reads a part of `face` back.
    pub fn from_bytes(bytes: &[u8], face: usize, slice_len: usize) -> Result<Self, String> {
        let [version, f, first, count] = read_head(bytes, PART_MAGIC, 20)?;
        if version != 1 || f != face {
            return Err("a checkpoint part belongs to another face".into());
        }
        if bytes.len() - 20 != count * slice_len {
            return Err("a checkpoint part's length does not match its header".into());
        }
        Ok(Self {
            first,
            slices: bytes[20..].to_vec(),
        })
    }

    /// Writes its slices into `field`; they must continue it at `next`.
    pub fn apply(&self, field: &mut FaceField, next: usize) -> Result<usize, String> {
        let n = field.slice_len();
        let count = self.slices.len() / n.max(1);
        if self.first != next || next + count > field.times {
            return Err(format!(
                "a checkpoint part starts at time {} where {next} was expected",
                self.first
            ));
        }
        field.insert(next, &self.slices);
        Ok(next + count)
    }
}

/// A face job's checkpoint: the digests of its parts, in time order.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Manifest {
    /// sha256 of each part blob.
    pub parts: Vec<String>,
}

/// What a face's sampling needs besides the mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaceSampling {
    /// The spheroid and its shells.
    pub spheroid: Spheroid,
    /// Texels per face edge.
    pub resolution: usize,
    /// Eq. 3.1's parameters (its seed is scrambled per face).
    pub kroon: KroonParams,
}

/// Why computing a face stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FaceError<E> {
    /// The tracer refused the input.
    #[error(transparent)]
    Trace(#[from] TraceError),
    /// Saving a part asked the computation to stop.
    #[error("stopped after a checkpoint")]
    Stopped(E),
}

/// Computes time samples `next..field.times` of `face` into `field`:
/// `positions(m)` is the posed mesh at time sample `m` (called on this
/// thread, a batch ahead: the next batch's scenes are built while one
/// traces). After every [`checkpoint_batch`] time samples (and at the
/// end) the new slices go to `save` as a [`Part`]; an `Err` from it stops
/// the computation, keeping what was saved.
pub fn compute_face<E>(
    sampling: &FaceSampling,
    face: usize,
    triangles: &[[u32; 3]],
    positions: &mut dyn FnMut(usize) -> Vec<Vec3>,
    field: &mut FaceField,
    next: usize,
    save: &mut dyn FnMut(Part, usize) -> Result<(), E>,
) -> Result<(), FaceError<E>> {
    let points = face_points(&sampling.spheroid, face, sampling.resolution);
    let times = field.times;
    let batch = checkpoint_batch(times);
    let end_of = |first: usize| (first + batch).min(times);
    let mut frames =
        |first: usize| -> Vec<Vec<Vec3>> { (first..end_of(first)).map(&mut *positions).collect() };
    // A checkpoint's time samples are traced as one batch; the next
    // batch's meshes are built while it traces (a GPU tracer leaves the
    // CPU idle meanwhile).
    let mut scenes = if next < times {
        face_scenes(&frames(next), triangles)?
    } else {
        Vec::new()
    };
    let mut first = next;
    while first < times {
        let end = end_of(first);
        let upcoming = (end < times).then(|| frames(end));
        let (slices, built) = rayon::join(
            || trace_face(&scenes, &points, face, &sampling.kroon),
            || upcoming.map(|f| face_scenes(&f, triangles)).transpose(),
        );
        let mut part = Part {
            first,
            slices: Vec::with_capacity((end - first) * points.len()),
        };
        for slice in slices? {
            part.slices.extend(slice.into_iter().map(quantise));
        }
        field.insert(first, &part.slices);
        save(part, end).map_err(FaceError::Stopped)?;
        scenes = built?.unwrap_or_default();
        first = end;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_interrupted_face_resumed_from_its_parts_equals_an_uninterrupted_one() {
        use crate::trace::shapes::icosphere;
        let sphere = icosphere(2, 0.5, Vec3::ZERO);
        // The sphere orbits the centre over the cycle.
        let times = 12;
        let mut positions = |m: usize| -> Vec<Vec3> {
            let a = std::f32::consts::TAU * m as f32 / times as f32;
            let offset = 0.4 * Vec3::new(a.cos(), 0.0, a.sin());
            sphere.positions.iter().map(|&p| p + offset).collect()
        };
        let sampling = FaceSampling {
            spheroid: Spheroid {
                centre: Vec3::ZERO,
                radii: Vec3::splat(1.0),
                outer: 1.5,
                inner: 0.3,
                shells: 3,
            },
            resolution: 4,
            kroon: KroonParams {
                samples: 32,
                max_distance: 2.0,
                alpha: 1.0,
                weight: 1.0,
                seed: 3,
            },
        };
        let run = |field: &mut FaceField,
                   next: usize,
                   stop_after: Option<usize>,
                   parts: &mut Vec<Vec<u8>>,
                   positions: &mut dyn FnMut(usize) -> Vec<Vec3>| {
            let n = field.slice_len();
            compute_face(
                &sampling,
                0,
                &sphere.triangles,
                positions,
                field,
                next,
                &mut |part: Part, done: usize| {
                    parts.push(part.to_bytes(0, n));
                    if stop_after.is_some_and(|s| done >= s) {
                        Err(())
                    } else {
                        Ok(())
                    }
                },
            )
        };
        let mut whole = FaceField::new(4, 3, times);
        let mut parts = Vec::new();
        run(&mut whole, 0, None, &mut parts, &mut positions).unwrap();
        assert_eq!(parts.len(), times, "a part per time sample at 12 samples");
        assert!(whole.values.iter().any(|&v| v > 0));
        // Stopped after 5 samples, then resumed from the saved parts only.
        let mut first = FaceField::new(4, 3, times);
        let mut saved = Vec::new();
        let stopped = run(&mut first, 0, Some(5), &mut saved, &mut positions);
        assert!(matches!(stopped, Err(FaceError::Stopped(()))));
        let mut resumed = FaceField::new(4, 3, times);
        let n = resumed.slice_len();
        let mut next = 0;
        for blob in &saved {
            next = Part::from_bytes(blob, 0, n)
                .unwrap()
                .apply(&mut resumed, next)
                .unwrap();
        }
        assert_eq!(next, 5);
        run(&mut resumed, next, None, &mut saved, &mut positions).unwrap();
        assert_eq!(resumed, whole, "the same bytes however it was interrupted");
        // The occlusion follows the sphere: the +x texels are darkest when
        // it is at +x (time 0) and lightest when it is at −x (time 6).
        let centre_texel = whole.texel(4 + 1);
        assert!(centre_texel[2 * times] > centre_texel[2 * times + 6]);
    }

    #[test]
    fn slices_land_texel_major_and_parts_rebuild_the_field() {
        let (res, shells, times) = (3, 2, 5);
        let mut whole = FaceField::new(res, shells, times);
        let n = whole.slice_len();
        let slice =
            |time: usize| -> Vec<u8> { (0..n).map(|p| (p * 7 + time * 31) as u8).collect() };
        for t in 0..times {
            whole.insert(t, &slice(t));
        }
        // Texel 4, shell 1, time 3 is slice 3's point 1·9 + 4.
        assert_eq!(whole.texel(4)[times + 3], slice(3)[9 + 4]);
        // Parts of 2, 2 and 1 slices through their blobs.
        let mut rebuilt = FaceField::new(res, shells, times);
        let mut next = 0;
        for (first, count) in [(0, 2), (2, 2), (4, 1)] {
            let part = Part {
                first,
                slices: (first..first + count).flat_map(slice).collect(),
            };
            let back = Part::from_bytes(&part.to_bytes(5, n), 5, n).unwrap();
            next = back.apply(&mut rebuilt, next).unwrap();
        }
        assert_eq!(next, times);
        assert_eq!(rebuilt, whole);
        let blob = whole.to_bytes();
        assert_eq!(
            FaceField::from_bytes(&blob, (res, shells, times)).unwrap(),
            whole
        );
        assert!(FaceField::from_bytes(&blob, (res, shells, 4)).is_err());
        // A part out of order or of another face is refused.
        let part = Part {
            first: 3,
            slices: slice(3),
        };
        assert!(part.apply(&mut rebuilt, 2).is_err());
        assert!(Part::from_bytes(&part.to_bytes(1, n), 2, n).is_err());
    }

    #[test]
    fn quantisation_is_within_half_a_step_and_batches_cover_the_cycle() {
        for v in [0.0, 0.1234, 0.5, 0.999, 1.0] {
            assert!((dequantise(quantise(v)) - v).abs() <= 0.5 / 255.0 + 1e-7);
        }
        assert_eq!(quantise(-1.0), 0);
        assert_eq!(quantise(f32::NAN), 0);
        assert_eq!(checkpoint_batch(255), 8);
        assert_eq!(checkpoint_batch(16), 1);
    }
}
