//! The `aobake` command line, run as a real process.

use std::{
    path::{Path, PathBuf},
    process::{Command, Output},
};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn sample(name: &str) -> PathBuf {
    repo().join("tests/data/characters").join(name)
}

fn aobake(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_aobake"))
        .args(args)
        .output()
        .unwrap()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn help_for_every_command() {
    for args in [&["--help"][..], &["inspect", "--help"], &["pose", "--help"]] {
        let out = aobake(args);
        assert!(out.status.success(), "{args:?}");
        assert!(stdout(&out).contains("Usage: aobake"), "{args:?}");
    }
}

#[test]
fn inspect_json_reports_counts_of_several_files() {
    let a = sample("SimpleSkin/SimpleSkin.gltf");
    let b = sample("RiggedFigure/RiggedFigure.glb");
    let out = aobake(&[
        "inspect",
        "--json",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let reports: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let r = reports.as_array().unwrap();
    assert_eq!(r.len(), 2);
    assert_eq!(r[0]["vertices"], 10);
    assert_eq!(r[0]["triangles"], 8);
    assert_eq!(r[0]["skin_joints"], serde_json::json!([2]));
    assert_eq!(r[1]["vertices"], 370);
    assert_eq!(r[1]["triangles"], 256);
    assert_eq!(r[1]["joints"], 19);
    assert_eq!(r[1]["clips"][0]["duration"], 1.25);
    assert_eq!(r[1]["pose_parameters"], 57);
    assert!(r[1]["diagonal"].as_f64().unwrap() > 0.0);
}

#[test]
fn inspect_text_names_clips() {
    let out = aobake(&[
        "inspect",
        sample("RiggedSimple/RiggedSimple.glb").to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let text = stdout(&out);
    assert!(text.contains("vertices     160"), "{text}");
    assert!(text.contains("animation_0"), "{text}");
}

/// Reads the vertex positions of a binary PLY written by `aobake pose`.
fn ply_positions(bytes: &[u8]) -> Vec<[f32; 3]> {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    let count: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .parse()
        .unwrap();
    (0..count)
        .map(|i| {
            let at = end + i * 24;
            let f = |k: usize| {
                f32::from_le_bytes(bytes[at + 4 * k..at + 4 * k + 4].try_into().unwrap())
            };
            [f(0), f(1), f(2)]
        })
        .collect()
}

#[test]
fn pose_writes_the_skinned_mesh_as_ply() {
    let dir = tempfile::tempdir().unwrap();
    let file = sample("RiggedSimple/RiggedSimple.glb");
    let bind = dir.path().join("bind.ply");
    let posed = dir.path().join("posed.ply");
    let out = aobake(&[
        "pose",
        file.to_str().unwrap(),
        "--out",
        bind.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = aobake(&[
        "pose",
        file.to_str().unwrap(),
        "--clip",
        "animation_0",
        "--time",
        "1.0",
        "--out",
        posed.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("160 vertices, 188 triangles"));
    let (b, p) = (
        ply_positions(&std::fs::read(&bind).unwrap()),
        ply_positions(&std::fs::read(&posed).unwrap()),
    );
    assert_eq!(b.len(), 160);
    assert_eq!(p.len(), 160);
    assert_ne!(b, p, "the clip moves the mesh");

    // Same through the library: the CLI writes core's skinning exactly.
    let bytes = std::fs::read(&file).unwrap();
    let imported = aobake_core::import_character(
        aobake_core::Upload::single(&bytes),
        &aobake_core::Limits::default(),
    )
    .unwrap();
    let c = &imported.character;
    let expect = c.skin(&aobake_core::Pose::sample(
        &c.skeleton,
        &imported.clips[0],
        1.0,
    ));
    for (got, want) in p.iter().zip(&expect.positions) {
        assert_eq!(*got, want.to_array());
    }
}

#[test]
fn pose_with_clips_from_a_second_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = sample("RiggedSimple/RiggedSimple.glb");
    let out_ply = dir.path().join("p.ply");
    let out = aobake(&[
        "pose",
        file.to_str().unwrap(),
        "--clips",
        file.to_str().unwrap(),
        "--clip",
        "animation_0",
        "--time",
        "0.5",
        "--out",
        out_ply.to_str().unwrap(),
        "--ascii",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        std::fs::read_to_string(&out_ply)
            .unwrap()
            .starts_with("ply\nformat ascii 1.0\n")
    );
}

#[test]
fn errors_are_clear_and_exit_nonzero() {
    let dir = tempfile::tempdir().unwrap();
    let file = sample("RiggedSimple/RiggedSimple.glb");
    let out = aobake(&[
        "pose",
        file.to_str().unwrap(),
        "--clip",
        "nope",
        "--time",
        "0",
        "--out",
        dir.path().join("x.ply").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("no clip named \"nope\"; the clips are: animation_0"),
        "{}",
        stderr(&out)
    );

    // A .gltf pointing outside its folder is refused, and the file beside it
    // is never read.
    let gltf = dir.path().join("evil.gltf");
    std::fs::write(
        &gltf,
        r#"{"asset":{"version":"2.0"},"buffers":[{"uri":"../../etc/passwd","byteLength":4}]}"#,
    )
    .unwrap();
    let out = aobake(&["inspect", gltf.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("`..` segments are not allowed"),
        "{}",
        stderr(&out)
    );

    let out = aobake(&["inspect", dir.path().join("missing.glb").to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("cannot read"), "{}", stderr(&out));
}
