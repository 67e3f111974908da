//! The C ABI as C sees it: the checked-in header is what cbindgen makes of
//! the crate now, and a C program compiled against it plays a baked asset
//! through the shared library with the same numbers as the Rust runtime.

use std::{
    path::{Path, PathBuf},
    process::Command,
};

use aobake_core::{
    Limits, Pose, Upload,
    bake::{Bake, BakeInputs, BakeParams, bake_in_process},
    import_character,
    method::Method,
};
use aobake_runtime::method::vertex::VertexAo;

fn crate_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn the_header_is_what_cbindgen_generates() {
    let mut generated = Vec::new();
    cbindgen::generate(crate_dir())
        .expect("cbindgen reads the crate")
        .write(&mut generated);
    let path = crate_dir().join("include/aobake_rt.h");
    if std::env::var_os("AOBAKE_BLESS").is_some() {
        std::fs::write(&path, &generated).unwrap();
    }
    let checked_in = std::fs::read(&path).unwrap_or_default();
    assert!(
        checked_in == generated,
        "include/aobake_rt.h is stale: AOBAKE_BLESS=1 cargo test -p aobake-runtime-capi rewrites it"
    );
}

/// The folder with the shared library: the test binary's own (target/…/deps).
fn library_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let deps = exe.parent().unwrap().to_path_buf();
    assert!(
        deps.join("libaobake_rt.so").is_file(),
        "the cdylib is built beside the tests in {}",
        deps.display()
    );
    deps
}

fn bake_rigged_figure(method: Method) -> (Vec<u8>, aobake_core::Character, Vec<aobake_core::Clip>) {
    let path = crate_dir().join("../../tests/data/characters/RiggedFigure/RiggedFigure.glb");
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let imported = import_character(Upload::single(&bytes), &Limits::default()).unwrap();
    let inputs = BakeInputs {
        character: imported.character.clone(),
        clips: imported.clips.clone(),
        character_digest: "character-digest".into(),
        clip_digests: Vec::new(),
        warnings: Vec::new(),
    };
    let mut params = BakeParams::new(method);
    params.poses = 96;
    params.samples = 64;
    params.eval_poses = 8;
    params.eval_fps = 15.0;
    let baked = bake_in_process(&Bake::new(&inputs, params).unwrap(), None).unwrap();
    (baked.asset, imported.character, imported.clips)
}

fn compile(dir: &Path) -> PathBuf {
    let exe = dir.join("play");
    let lib = library_dir();
    let status = Command::new(std::env::var("CC").unwrap_or_else(|_| "cc".into()))
        .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-I"])
        .arg(crate_dir().join("include"))
        .arg(crate_dir().join("tests/c/play.c"))
        .arg("-L")
        .arg(&lib)
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-laobake_rt")
        .arg("-o")
        .arg(&exe)
        .status()
        .expect("a C compiler (cc)");
    assert!(status.success(), "play.c compiles against the header");
    exe
}

#[test]
fn a_c_program_plays_an_asset_as_the_runtime_does() {
    let dir = std::env::temp_dir().join(format!("aobake-capi-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let exe = compile(&dir);
    for method in [Method::VertexLinear, Method::VertexClustered] {
        let (asset, character, clips) = bake_rigged_figure(method);
        let asset_path = dir.join("figure.aobake");
        std::fs::write(&asset_path, &asset).unwrap();
        // A frame of the clip, every node by name, as an engine's
        // animation gives it: Rust's shortest round-trip floats, which C's
        // strtof reads back exactly.
        let pose = Pose::sample(&character.skeleton, &clips[0], 0.7);
        let mut text = String::new();
        for (node, t) in character.skeleton.nodes.iter().zip(&pose.locals) {
            let name = node.name.as_deref().expect("RiggedFigure names its nodes");
            let numbers: Vec<String> = t
                .translation
                .to_array()
                .iter()
                .chain(&t.rotation.to_array())
                .chain(&t.scale.to_array())
                .map(|x| format!("{x:e}"))
                .collect();
            text.push_str(&format!("{name}\t{}\n", numbers.join(" ")));
        }
        let pose_path = dir.join("pose.txt");
        std::fs::write(&pose_path, text).unwrap();
        let out_path = dir.join("out.bin");
        // The library the test was built with, by the rpath: cargo's
        // LD_LIBRARY_PATH would put target/debug first, where an older
        // build's copy may lie.
        let run = Command::new(&exe)
            .env_remove("LD_LIBRARY_PATH")
            .args([&asset_path, &pose_path, &out_path])
            .output()
            .unwrap();
        assert!(
            run.status.success(),
            "{method:?}: {}{}",
            String::from_utf8_lossy(&run.stdout),
            String::from_utf8_lossy(&run.stderr)
        );
        let floats: Vec<f32> = std::fs::read(&out_path)
            .unwrap()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        let mut rust = VertexAo::from_bytes(&asset).unwrap();
        for (n, t) in pose.locals.iter().enumerate() {
            assert!(rust.set_local(n, *t));
        }
        let (weights, ao) = floats.split_at(rust.weight_count());
        assert_eq!(weights, rust.weights(), "{method:?}: weights bit for bit");
        assert_eq!(ao, rust.evaluate(), "{method:?}: AO bit for bit");
        assert!(ao.iter().any(|&a| a > 0.0), "{method:?}: some occlusion");
    }
    std::fs::remove_dir_all(&dir).ok();
}
