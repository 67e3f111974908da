//! Import from untrusted bytes must never panic: any input either imports
//! (and then poses without panicking) or returns an error.
#![no_main]

use aobake_core::{Limits, Pose, Upload, import_character, import_clips, summary::Summary};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // Small limits keep each run fast; the checks are the same.
    let limits = Limits {
        max_vertices: 100_000,
        max_triangles: 100_000,
        max_keyframes: 100_000,
        ..Limits::default()
    };
    let Ok(imported) = import_character(Upload::single(data), &limits) else { return };
    let _ = Summary::of(&imported.character, &imported.clips);
    let _ = imported.character.skin(&Pose::bind(&imported.character));
    let _ = import_clips(Upload::single(data), &imported.character, &limits);
});
