//! The `aobake` command line, run as a real process.

use std::{
    path::{Path, PathBuf},
    process::{Command, Output},
};

use nix::sys::signal::Signal;

#[path = "integration/bake.rs"]
mod bake;
#[path = "integration/docker.rs"]
mod docker;
#[path = "integration/export_gltf.rs"]
mod export_gltf;

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
    for args in [
        &["--help"][..],
        &["inspect", "--help"],
        &["pose", "--help"],
        &["trace", "--help"],
        &["bench", "trace", "--help"],
        &["bake", "--help"],
        &["eval", "--help"],
    ] {
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
    // 19 joints × 3, less the body root's rotation (it turns the whole mesh).
    assert_eq!(r[1]["pose_parameters"], 54);
    assert!(r[1]["diagonal"].as_f64().unwrap() > 0.0);
}

/// A file that cannot be read is named, the others are still described,
/// and the command exits 1.
#[test]
fn inspect_goes_on_past_a_file_it_cannot_read() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.glb");
    std::fs::write(&bad, b"not a glTF").unwrap();
    let good = sample("RiggedSimple/RiggedSimple.glb");
    let files = [bad.to_str().unwrap(), good.to_str().unwrap()];
    let out = aobake(&[&["inspect"][..], &files].concat());
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stdout(&out).contains("vertices     160"),
        "{}",
        stdout(&out)
    );
    assert!(
        stderr(&out).contains("bad.glb") && stderr(&out).contains("1 of 2 files could not be read"),
        "{}",
        stderr(&out)
    );
    let out = aobake(&[&["inspect", "--json"][..], &files].concat());
    assert_eq!(out.status.code(), Some(1));
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (&r[0]["kind"], &r[1]["kind"]),
        (&"error".into(), &"character".into())
    );
    assert!(r[0]["error"].as_str().unwrap().contains("GLB"), "{}", r[0]);
    // Alone, as JSON too.
    let out = aobake(&["inspect", "--json", files[0]]);
    assert_eq!(out.status.code(), Some(1));
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r[0]["kind"], "error");
}

/// CesiumMan rests lying along z (y from −0.57 to 0.57) and its clip
/// stands him up: the bounds are the frames', not the rest pose's.
#[test]
fn inspect_bounds_are_the_clip_frames() {
    let out = aobake(&[
        "inspect",
        "--json",
        sample("CesiumMan/CesiumMan.glb").to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let [lo, hi] = [0, 1].map(|i| r[0]["bounds"][i][1].as_f64().unwrap());
    assert!(lo > -0.1 && hi > 1.4, "y from {lo} to {hi}");
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
    let out = pose_ply(&file, "1.0", &posed);
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

    // A negative number reaches the parameter's own check, not clap's
    // "unexpected argument".
    let out = aobake(&[
        "params",
        "--method",
        "vertex-linear",
        "--max-distance",
        "-1",
    ]);
    assert!(
        stderr(&out).contains("max_distance must be positive"),
        "{}",
        stderr(&out)
    );
    // A server address without its scheme is named, with the fix.
    let server = ["--server", "127.0.0.1:8080", "--token", "t"];
    for args in [&["status", "1"][..], &["worker"]] {
        let out = aobake(&[args, &server[..]].concat());
        assert!(
            stderr(&out).contains("is not a URL") && stderr(&out).contains("http://127.0.0.1:8080"),
            "{args:?}: {}",
            stderr(&out)
        );
    }
}

#[test]
fn export_writes_the_shaders_for_engines_and_says_what_it_needs() {
    let dir = tempfile::tempdir().unwrap();
    let out = aobake(&["export", "--shaders", dir.path().to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("wrote 60 shader files"),
        "{}",
        stderr(&out)
    );
    for file in [
        "glsl450/vertex_ao.cs_main.comp",
        "glsl-es310/vertex_ao.cs_sparse.comp",
        "glsl-es300/vertex_ao_vs.vs_main.vert",
        "glsl-es300/vertex_ao_vs.fs_main.frag",
        "glsl-es300/cubemap_ao_vs.vs_main.vert",
        "glsl-es300/grid_ao_vs.vs_main.vert",
        "glsl-es300/texel_ao.fs_main.frag",
        "hlsl-sm5_1/grid_ao.hlsl",
        "hlsl-sm6_0/cubemap_ao.hlsl",
        "msl2_1/vertex_ao.metal",
    ] {
        let text = std::fs::read_to_string(dir.path().join(file)).unwrap();
        assert!(!text.is_empty(), "{file}");
    }
    // Each shader's binding table beside it: naga's GLSL ES names, which
    // WebGL2 binds by.
    let table =
        std::fs::read_to_string(dir.path().join("glsl-es300/vertex_ao_vs.bindings.md")).unwrap();
    assert!(
        table.contains("vs_main: `_group_0_binding_4_vs`")
            && table.contains("AobakeVertexVsParams"),
        "{table}"
    );
    let spirv = std::fs::read(dir.path().join("spirv1_3/vertex_ao.spv")).unwrap();
    assert_eq!(
        spirv[..4],
        0x0723_0203u32.to_le_bytes(),
        "the SPIR-V magic number"
    );
    // Nothing to export, and --exr without an asset, are usage errors.
    let out = aobake(&["export"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("--exr") && stderr(&out).contains("--shaders"));
    let out = aobake(&["export", "--exr", dir.path().to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("<ASSET>"), "{}", stderr(&out));
}

/// Reads `index,occlusion` rows, checking the header and the index column.
fn occlusion_csv(path: &Path) -> Vec<f32> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("index,occlusion"));
    lines
        .enumerate()
        .map(|(i, line)| {
            let (index, value) = line.split_once(',').unwrap();
            assert_eq!(index.parse::<usize>().unwrap(), i);
            value.parse().unwrap()
        })
        .collect()
}

/// `aobake pose FILE --clip animation_0 --time TIME --out PLY`, which must
/// succeed.
fn pose_ply(file: &Path, time: &str, ply: &Path) -> Output {
    let out = aobake(&[
        "pose",
        file.to_str().unwrap(),
        "--clip",
        "animation_0",
        "--time",
        time,
        "--out",
        ply.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    out
}

/// `aobake trace --mesh MESH --out CSV ARGS...`, which must succeed.
fn trace_ok(mesh: &Path, csv: &Path, args: &[&str]) -> Output {
    let mut all = vec![
        "trace",
        "--mesh",
        mesh.to_str().unwrap(),
        "--out",
        csv.to_str().unwrap(),
    ];
    all.extend_from_slice(args);
    let out = aobake(&all);
    assert!(out.status.success(), "{}", stderr(&out));
    out
}

#[test]
fn trace_writes_occlusion_per_vertex_the_same_on_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let file = sample("RiggedFigure/RiggedFigure.glb");
    let trace = |name: &str, extra: &[&str]| {
        let out_csv = dir.path().join(name);
        let mut args = vec!["--clip", "animation_0", "--time", "0.6", "--samples", "64"];
        args.extend_from_slice(extra);
        let out = trace_ok(&file, &out_csv, &args);
        assert!(stderr(&out).contains("370 vertices"), "{}", stderr(&out));
        out_csv
    };
    let one = trace("one.csv", &["--threads", "1"]);
    let two = trace("two.csv", &["--threads", "2"]);
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&two).unwrap());
    let values = occlusion_csv(&one);
    assert_eq!(values.len(), 370);
    assert!(values.iter().all(|v| (0.0..=1.0).contains(v)));
    let mean = values.iter().sum::<f32>() / 370.0;
    assert!(mean > 0.02 && mean < 0.6, "mean occlusion {mean}");

    let other_seed = occlusion_csv(&trace("seed.csv", &["--seed", "9"]));
    assert_ne!(values, other_seed);
    // A ground under the feet only adds occlusion.
    let grounded = occlusion_csv(&trace("ground.csv", &["--ground"]));
    let more = values.iter().zip(&grounded).filter(|(a, b)| b > a).count();
    assert!(more > 10, "{more} vertices darkened by the ground");

    // The same pose written by `aobake pose` and traced as PLY (positions
    // and normals as written) gives the same bytes.
    let ply = dir.path().join("posed.ply");
    pose_ply(&file, "0.6", &ply);
    let from_ply = dir.path().join("ply.csv");
    trace_ok(&ply, &from_ply, &["--samples", "64"]);
    assert_eq!(occlusion_csv(&from_ply), values);
}

#[test]
fn trace_rejects_bad_arguments_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let file = sample("RiggedSimple/RiggedSimple.glb");
    let out_csv = dir.path().join("x.csv");
    let run = |mesh: &Path, extra: &[&str]| {
        let mut args = vec![
            "trace",
            "--mesh",
            mesh.to_str().unwrap(),
            "--out",
            out_csv.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        aobake(&args)
    };
    for (extra, message) in [
        (
            &["--samples", "0"][..],
            "samples must be between 1 and 65536",
        ),
        (&["--max-distance=-2"], "max_distance must be positive"),
        (&["--threads", "0"], "--threads must be at least 1"),
    ] {
        let out = run(&file, extra);
        assert!(!out.status.success(), "{extra:?}");
        assert!(
            stderr(&out).contains(message),
            "{extra:?}: {}",
            stderr(&out)
        );
    }
    assert!(!out_csv.exists(), "nothing is written on error");

    let bad_ply = dir.path().join("bad.ply");
    std::fs::write(
        &bad_ply,
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\nnan\n",
    )
    .unwrap();
    let out = run(&bad_ply, &[]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("bad.ply"), "{}", stderr(&out));
}

/// `../shared/tools/blender-ao/bake_vertex_ao.py`, when it is there.
fn blender_script() -> Option<PathBuf> {
    let script = repo().join("../shared/tools/blender-ao/bake_vertex_ao.py");
    script.is_file().then_some(script)
}

/// Blender's per-vertex AO (1 = open) of a PLY at 1024 samples.
fn blender_ao(script: &Path, ply: &Path, csv: &Path, seed: u32) -> Vec<f32> {
    let out = Command::new("blender")
        .args(["-b", "--factory-startup", "--python"])
        .arg(script)
        .arg("--")
        .arg("--mesh")
        .arg(ply)
        .arg("--out")
        .arg(csv)
        .args([
            "--samples",
            "1024",
            "--distance",
            "100",
            "--normals",
            "file",
        ])
        .args(["--seed", &seed.to_string()])
        .output()
        .expect("blender runs");
    assert!(out.status.success(), "{}", stderr(&out));
    let text = std::fs::read_to_string(csv).unwrap();
    text.lines()
        .skip(1)
        .map(|l| l.split_once(',').unwrap().1.parse().unwrap())
        .collect()
}

fn rms(a: &[f32], b: &[f32]) -> f64 {
    let sum: f64 = a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum();
    (sum / a.len() as f64).sqrt()
}

/// CesiumMan at a clip time, traced by aobake and baked by Blender 3.4
/// Cycles at 1024 samples with two seeds each. Needs `blender` on the PATH
/// and `../shared` (the reference tool and the character):
/// `cargo test -p aobake-server --test integration -- --ignored blender`.
#[test]
#[ignore = "needs Blender 3.4 and ../shared/tools/blender-ao"]
fn trace_agrees_with_blender_on_a_posed_character() {
    let script = blender_script().expect("../shared/tools/blender-ao");
    let character = repo().join("../shared/data/CesiumMan/CesiumMan.glb");
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("posed.ply");
    pose_ply(&character, "1.0", &ply);
    let ours: Vec<Vec<f32>> = (0..2)
        .map(|seed| {
            let csv = dir.path().join(format!("ours{seed}.csv"));
            let seed = seed.to_string();
            let args = [
                "--samples",
                "1024",
                "--max-distance",
                "100",
                "--seed",
                &seed,
            ];
            trace_ok(&ply, &csv, &args);
            occlusion_csv(&csv).into_iter().map(|o| 1.0 - o).collect()
        })
        .collect();
    let theirs: Vec<Vec<f32>> = (0..2)
        .map(|seed| {
            blender_ao(
                &script,
                &ply,
                &dir.path().join(format!("b{seed}.csv")),
                seed,
            )
        })
        .collect();

    // Vertices where the two conventions agree: not on an open boundary
    // (UV seams split CesiumMan's vertices) and with every own triangle
    // facing within 90° of the vertex normal. Elsewhere Blender counts the
    // space below a triangle's plane as solid (its "shadow terminator"
    // rule) where aobake lets rays through an open edge or a fold.
    let mesh = aobake_core::import::ply::read(
        &std::fs::read(&ply).unwrap(),
        &aobake_core::Limits::default(),
    )
    .unwrap();
    let normals = mesh.normals.unwrap();
    let mut edges = std::collections::HashMap::new();
    let mut folded = vec![false; normals.len()];
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
        let face = (b - a).cross(c - a).normalize_or_zero();
        for k in 0..3 {
            let (i, j) = (t[k], t[(k + 1) % 3]);
            *edges.entry((i.min(j), i.max(j))).or_insert(0) += 1;
            folded[t[k] as usize] |= face.dot(normals[t[k] as usize]) < 0.0;
        }
    }
    let mut boundary = vec![false; normals.len()];
    for ((i, j), n) in edges {
        if n == 1 {
            boundary[i as usize] = true;
            boundary[j as usize] = true;
        }
    }
    let agree: Vec<usize> = (0..normals.len())
        .filter(|&i| !boundary[i] && !folded[i])
        .collect();
    assert!(agree.len() > normals.len() / 3, "{} vertices", agree.len());
    let pick = |v: &[f32]| agree.iter().map(|&i| v[i]).collect::<Vec<_>>();
    let (o0, o1, b0, b1) = (
        pick(&ours[0]),
        pick(&ours[1]),
        pick(&theirs[0]),
        pick(&theirs[1]),
    );
    // Seed-to-seed noise of each, and what it allows between one run of
    // each.
    let noise = (rms(&o0, &o1).powi(2) / 2.0 + rms(&b0, &b1).powi(2) / 2.0).sqrt();
    let between = rms(&o0, &b0);
    let bias = o0
        .iter()
        .zip(&b0)
        .map(|(x, y)| f64::from(x - y))
        .sum::<f64>()
        / o0.len() as f64;
    eprintln!(
        "{} of {} vertices compared: RMSE {between:.5}, noise allows {noise:.5}, bias {bias:+.5}; whole mesh RMSE {:.5}",
        agree.len(),
        normals.len(),
        rms(&ours[0], &theirs[0])
    );
    assert!(noise < 0.003, "noise {noise}");
    assert!(
        between < 2.0 * noise,
        "RMSE {between} against noise {noise}"
    );
    assert!(bias.abs() < 1e-3, "bias {bias}");
}

/// A command whose stdout is a pipe that closes ends quietly: no panic,
/// no backtrace, the status a Unix tool killed by SIGPIPE gets (141).
#[test]
fn a_closed_output_pipe_ends_a_command_quietly() {
    for args in [&["openapi"][..], &["params", "--method", "grid"]] {
        // The reader is gone before the command starts: however short its
        // output, its first write meets a closed pipe (closing it after
        // the spawn raced a short output into the pipe's buffer).
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let child = Command::new(env!("CARGO_BIN_EXE_aobake"))
            .args(args)
            .stdout(writer)
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let out = child.wait_with_output().unwrap();
        assert_eq!(out.status.code(), Some(141), "{args:?}: {}", stderr(&out));
        assert!(
            !stderr(&out).contains("panicked"),
            "{args:?}: {}",
            stderr(&out)
        );
    }
}

/// `aobake params --method M` prints the common parameters and M's own
/// section, not every method's.
#[test]
fn params_prints_the_methods_own_parameters() {
    for (method, own) in [
        ("vertex-linear", "linear"),
        ("vertex-clustered", "clustered"),
        ("grid", "grid"),
        ("cubemap-discrete", "cubemap"),
        ("cubemap-continuous", "cubemap"),
    ] {
        let out = aobake(&["params", "--method", method]);
        assert!(out.status.success(), "{}", stderr(&out));
        let p: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let sections: Vec<&str> = ["linear", "clustered", "grid", "cubemap"]
            .into_iter()
            .filter(|s| p.get(*s).is_some())
            .collect();
        assert_eq!(sections, [own], "{method}");
        assert_eq!(p["method"], method);
    }
    // A flag of another method is refused, not silently dropped.
    for args in [
        &["--method", "grid", "--ridge", "0.5"][..],
        &["--method", "vertex-linear", "--pose-clusters", "3"],
    ] {
        let out = aobake(&[&["params"][..], args].concat());
        assert!(!out.status.success(), "{args:?}");
        assert!(
            stderr(&out).contains("is an option of vertex-"),
            "{}",
            stderr(&out)
        );
    }
    // --ridge fixes vertex-linear's ridge instead of a cross-validated one.
    let out = aobake(&["params", "--method", "vertex-linear", "--ridge", "0.5"]);
    let p: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (&p["linear"]["ridge"], &p["linear"]["ridge_cv"]),
        (&0.5.into(), &false.into())
    );
}

/// A client command without a token says where it looked for one.
#[test]
fn a_client_without_a_token_says_where_it_looked() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_aobake"))
        .args(["status", "1", "--data"])
        .arg(dir.path().join("nowhere"))
        .env_remove("AOBAKE_TOKEN")
        .env_remove("AOBAKE_DATA")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let said = stderr(&out);
    assert!(
        said.contains("--token") && said.contains("nowhere/admin.token"),
        "{said}"
    );
}

/// `aobake serve` run as a service (no `XDG_RUNTIME_DIR`): its local
/// workers get a private runtime folder under the data folder, so Mesa's
/// drivers, which they open to look for a GPU, print no
/// "XDG_RUNTIME_DIR is invalid" errors at every start.
#[test]
fn local_workers_get_a_runtime_folder_and_print_no_mesa_noise() {
    use std::io::Read as _;
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let mut serve = serve_command(&data, 1)
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("AOBAKE_ADMIN_TOKEN")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The worker has looked for its GPU and polled once by then.
    std::thread::sleep(std::time::Duration::from_secs(6));
    signal(serve.id(), Signal::SIGTERM);
    let mut text = String::new();
    serve
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut text)
        .unwrap();
    serve
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut text)
        .unwrap();
    let _ = serve.wait();
    assert!(text.contains("listening on"), "{text}");
    assert!(!text.contains("XDG_RUNTIME_DIR"), "{text}");
    // Its lines say when (the start's too, and the local worker's
    // tracer), and the generated admin secret is in its file, not in the
    // log.
    for said in ["listening on", "admin token: generated into", "tracer: "] {
        let line = text
            .lines()
            .find(|l| l.contains(said))
            .unwrap_or_else(|| panic!("{said}: {text}"));
        let stamp = line.split(' ').next().unwrap();
        assert!(humantime::parse_rfc3339(stamp).is_ok(), "{line}");
    }
    let secret = std::fs::read_to_string(data.join("admin.token")).unwrap();
    assert!(!text.contains(secret.trim()), "{text}");
    let run = data.join("run");
    assert!(run.is_dir(), "{text}");
    use std::os::unix::fs::PermissionsExt as _;
    assert_eq!(
        std::fs::metadata(&run).unwrap().permissions().mode() & 0o777,
        0o700
    );
}

/// `aobake serve --listen 127.0.0.1:0 --workers N --data DATA`.
fn serve_command(data: &Path, workers: usize) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_aobake"));
    command
        .args(["serve", "--listen", "127.0.0.1:0", "--workers"])
        .arg(workers.to_string())
        .arg("--data")
        .arg(data);
    command
}

/// Sends `signal` to process `pid` (gone already: nothing to do).
fn signal(pid: u32, signal: Signal) {
    let pid = nix::unistd::Pid::from_raw(i32::try_from(pid).expect("a pid"));
    let _ = nix::sys::signal::kill(pid, signal);
}

/// The pids of `pid`'s children (any of its threads may have started
/// them).
fn children(pid: u32) -> Vec<u32> {
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return Vec::new();
    };
    tasks
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("children")).ok())
        .flat_map(|c| {
            c.split_whitespace()
                .filter_map(|p| p.parse().ok())
                .collect::<Vec<u32>>()
        })
        .collect()
}

/// Whether process `pid` still runs (not gone, not a zombie).
fn running(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|stat| {
        // The state follows the command's closing parenthesis.
        stat.rsplit_once(") ")
            .is_some_and(|(_, rest)| !rest.starts_with('Z') && !rest.starts_with('X'))
    })
}

/// `aobake serve` killed outright (SIGKILL: no chance to stop its
/// workers) does not leave its local workers polling a server that has
/// gone: the pipe it gave them closes, and they stop.
#[test]
fn local_workers_stop_when_serve_is_killed_outright() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let log = std::fs::File::create(dir.path().join("serve.log")).unwrap();
    let mut serve = serve_command(&data, 1)
        .stdout(log.try_clone().unwrap())
        .stderr(log)
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    let worker = loop {
        if let Some(&w) = children(serve.id()).first() {
            break w;
        }
        assert!(
            started.elapsed() < std::time::Duration::from_secs(30),
            "no local worker started"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    // Well into its first long poll.
    std::thread::sleep(std::time::Duration::from_secs(2));
    assert!(running(worker));
    serve.kill().unwrap();
    serve.wait().unwrap();
    let killed = std::time::Instant::now();
    while running(worker) && killed.elapsed() < std::time::Duration::from_secs(10) {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let outlived = running(worker);
    if outlived {
        signal(worker, Signal::SIGKILL);
    }
    let text = std::fs::read_to_string(dir.path().join("serve.log")).unwrap();
    assert!(!outlived, "the worker outlived its serve by 10 s\n{text}");
    assert!(text.contains("has gone; stopping"), "{text}");
}

/// A command that opens the GPU where no desktop session is (a container,
/// CI: no `XDG_RUNTIME_DIR`, no display) runs itself again in place with
/// Mesa's device-select layer off: the same pid, now with
/// `NODEVICE_SELECT=1`, and no Wayland errors; not where a device was
/// chosen through the layer; and a bake writes the same bytes either way.
#[test]
fn a_gpu_command_without_a_session_turns_off_the_display_layer_in_place() {
    let dir = tempfile::tempdir().unwrap();
    // A worker of a server that is not there: it opens the GPU, then
    // retries its lease until stopped.
    let worker = |chosen: bool| {
        let log = dir.path().join(format!("worker-{chosen}.log"));
        let mut command = Command::new(env!("CARGO_BIN_EXE_aobake"));
        command
            .args(["worker", "--server", "http://127.0.0.1:9", "--token", "t"])
            .env_remove("XDG_RUNTIME_DIR")
            .env_remove("DISPLAY")
            .env_remove("WAYLAND_DISPLAY")
            .env_remove("DRI_PRIME")
            .env_remove("NODEVICE_SELECT")
            .env_remove("MESA_VK_DEVICE_SELECT")
            .stdout(std::process::Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap());
        if chosen {
            command.env("MESA_VK_DEVICE_SELECT", "list-not");
        }
        let mut child = command.spawn().unwrap();
        // Past its tracer's line, into its lease retries.
        let started = std::time::Instant::now();
        while !std::fs::read_to_string(&log)
            .unwrap()
            .contains("cannot lease")
            && started.elapsed() < std::time::Duration::from_secs(30)
        {
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        let environ = std::fs::read(format!("/proc/{}/environ", child.id())).unwrap_or_default();
        signal(child.id(), Signal::SIGTERM);
        child.wait().unwrap();
        let off = environ
            .split(|&b| b == 0)
            .any(|v| v == b"NODEVICE_SELECT=1");
        (off, std::fs::read_to_string(&log).unwrap())
    };
    let (off, said) = worker(false);
    assert!(off, "the same pid runs with the layer off\n{said}");
    assert!(said.contains("tracer"), "{said}");
    assert!(!said.contains("XDG_RUNTIME_DIR"), "{said}");
    let (off, said) = worker(true);
    assert!(!off, "a device chosen through the layer keeps it\n{said}");

    let bake = |name: &str, session: bool| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_aobake"));
        command
            .args(["bake", "--method", "vertex-linear", "--poses", "16"])
            .args(["--samples", "16", "--tracer", "cpu", "--out"])
            .arg(dir.path().join(format!("{name}.aob")))
            .arg("--report")
            .arg(dir.path().join(format!("{name}.json")))
            .arg(sample("RiggedSimple/RiggedSimple.glb"))
            .env_remove("NODEVICE_SELECT")
            .env_remove("MESA_VK_DEVICE_SELECT");
        if session {
            command.env("XDG_RUNTIME_DIR", dir.path());
        } else {
            command.env_remove("XDG_RUNTIME_DIR");
        }
        let out = command.output().unwrap();
        assert!(out.status.success(), "{}", stderr(&out));
        std::fs::read(dir.path().join(format!("{name}.aob"))).unwrap()
    };
    assert_eq!(
        bake("without", false),
        bake("with", true),
        "the same bytes with and without a session"
    );
}

/// Starts `aobake serve --workers N` on `data` (with `admin` as its admin
/// token when given) and waits for its URL; `extra` are more flags.
fn start_serve(
    data: &Path,
    admin: Option<&str>,
    workers: usize,
    extra: &[&str],
) -> (std::process::Child, String) {
    let url_file = data.join("server.url");
    let _ = std::fs::remove_file(&url_file);
    let mut command = serve_command(data, workers);
    command
        .args(extra)
        .stdout(std::fs::File::create(data.with_extension("stdout")).unwrap())
        .stderr(std::fs::File::create(data.with_extension("stderr")).unwrap());
    match admin {
        Some(t) => command.env("AOBAKE_ADMIN_TOKEN", t),
        None => command.env_remove("AOBAKE_ADMIN_TOKEN"),
    };
    let mut child = command.spawn().unwrap();
    let started = std::time::Instant::now();
    let url = loop {
        if let Ok(url) = std::fs::read_to_string(&url_file) {
            break url;
        }
        if started.elapsed() > std::time::Duration::from_secs(30) {
            let _ = child.kill();
            let _ = child.wait();
            let said = std::fs::read_to_string(data.with_extension("stderr")).unwrap_or_default();
            panic!("serve did not start\n{said}");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    (child, url)
}

/// Stops `serve` as an operator does (SIGTERM) and waits for it.
fn stop_serve(mut serve: std::process::Child) {
    signal(serve.id(), Signal::SIGTERM);
    serve.wait().unwrap();
}

/// Switching `aobake serve` to an admin token of one's own leaves no
/// revoked token file for clients to pick up, the demo's dashboard token
/// and the local workers' go with the start that made them (a start
/// without local workers makes them none), a client whose token is
/// refused is told where it came from, and one that cannot reach the
/// server is told where its address came from (the stopped server's
/// `server.url`).
#[test]
fn a_restart_leaves_no_revoked_token_behind_and_a_refusal_names_the_tokens_source() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let (serve, first_url) = start_serve(&data, None, 1, &["--demo"]);
    let generated = std::fs::read_to_string(data.join("admin.token")).unwrap();
    // The tokens a start makes are named after it (host, data folder).
    let list = Command::new(env!("CARGO_BIN_EXE_aobake"))
        .args(["token", "list", "--json", "--server", &first_url, "--token"])
        .arg(generated.trim())
        .output()
        .unwrap();
    assert!(list.status.success(), "{}", stderr(&list));
    let tokens: serde_json::Value = serde_json::from_slice(&list.stdout).unwrap();
    let mut names: Vec<&str> = tokens
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["name"].as_str().unwrap())
        .collect();
    names.sort_unstable();
    let origin = format!(
        " (serve on {}, {})",
        aobake_server::serve::host_name(),
        std::path::absolute(&data).unwrap().display()
    );
    assert_eq!(
        names,
        ["admin", "demo dashboard", "local workers"].map(|n| format!("{n}{origin}")),
        "{tokens}"
    );
    // The demo uploads and submits through the API: wait for its line.
    let started = std::time::Instant::now();
    while !std::fs::read_to_string(data.with_extension("stdout"))
        .unwrap()
        .contains("demo:")
    {
        assert!(
            started.elapsed() < std::time::Duration::from_secs(60),
            "no demo"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    stop_serve(serve);
    // A client folder that kept the old token file.
    let stale = dir.path().join("stale");
    std::fs::create_dir(&stale).unwrap();
    std::fs::write(stale.join("admin.token"), &generated).unwrap();

    let admin = "an-admin-token-of-the-operators-own-0123456789";
    let (serve, url) = start_serve(&data, Some(admin), 0, &[]);
    let said = std::fs::read_to_string(data.with_extension("stdout")).unwrap();
    assert!(!data.join("admin.token").exists(), "{said}");
    assert!(said.contains("now revoked"), "{said}");
    let list = Command::new(env!("CARGO_BIN_EXE_aobake"))
        .args([
            "token", "list", "--json", "--server", &url, "--token", admin,
        ])
        .output()
        .unwrap();
    assert!(list.status.success(), "{}", stderr(&list));
    let tokens: serde_json::Value = serde_json::from_slice(&list.stdout).unwrap();
    let names: Vec<&str> = tokens
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["name"].as_str().unwrap())
        .collect();
    // The first start's demo and local-workers tokens are revoked, and a
    // start without local workers makes them none.
    assert_eq!(names, ["admin"], "{names:?}");
    let refused = Command::new(env!("CARGO_BIN_EXE_aobake"))
        .args(["status", "1", "--server", &url, "--data"])
        .arg(&stale)
        .env_remove("AOBAKE_TOKEN")
        .output()
        .unwrap();
    stop_serve(serve);
    assert!(!refused.status.success());
    let text = stderr(&refused);
    assert!(
        text.contains("refused the token from")
            && text.contains("admin.token")
            && text.contains("401"),
        "{text}"
    );
    // The stopped server's address, left in its data folder, is named as
    // where the client took it from.
    let unreached = Command::new(env!("CARGO_BIN_EXE_aobake"))
        .args(["status", "1", "--token", admin, "--data"])
        .arg(&data)
        .env_remove("AOBAKE_SERVER")
        .output()
        .unwrap();
    assert_eq!(unreached.status.code(), Some(7), "{}", stderr(&unreached));
    let text = stderr(&unreached);
    assert!(
        text.contains(&format!(
            "the server's address came from {}:",
            data.join("server.url").display()
        )) && text.contains("is that server running?"),
        "{text}"
    );
}

/// A revoked admin secret stays revoked when a server starts with it
/// again (a restart, another server of a fleet): the start says so and
/// goes on without it, and the other admin token still works.
#[test]
fn a_revoked_admin_token_stays_revoked_across_restarts() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let leaked = "an-admin-token-that-leaked-0123456789abcdef";
    let aobake = |url: &str, token: &str, args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_aobake"))
            .args(args)
            .args(["--server", url, "--token", token])
            .output()
            .unwrap()
    };
    let (serve, url) = start_serve(&data, Some(leaked), 0, &[]);
    let made = aobake(
        &url,
        leaked,
        &["token", "create", "--scope", "admin", "--name", "ops"],
    );
    assert!(made.status.success(), "{}", stderr(&made));
    let other = String::from_utf8(made.stdout).unwrap().trim().to_owned();
    let list = aobake(&url, &other, &["token", "list", "--json"]);
    let tokens: serde_json::Value = serde_json::from_slice(&list.stdout).unwrap();
    let id = tokens
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["name"] == "admin")
        .unwrap()["id"]
        .as_str()
        .unwrap()
        .to_owned();
    let revoked = aobake(&url, &other, &["token", "revoke", &id]);
    assert!(revoked.status.success(), "{}", stderr(&revoked));
    stop_serve(serve);

    let (serve, url) = start_serve(&data, Some(leaked), 0, &[]);
    let said = std::fs::read_to_string(data.with_extension("stderr")).unwrap();
    let refused = aobake(&url, leaked, &["token", "list"]);
    let still = aobake(&url, &other, &["token", "list", "--json"]);
    stop_serve(serve);
    assert!(said.contains("AOBAKE_ADMIN_TOKEN was revoked"), "{said}");
    assert!(!refused.status.success() && stderr(&refused).contains("401"));
    assert!(still.status.success(), "{}", stderr(&still));
    let tokens: serde_json::Value = serde_json::from_slice(&still.stdout).unwrap();
    assert!(
        tokens
            .as_array()
            .unwrap()
            .iter()
            .all(|t| t["id"] != id.as_str()),
        "{tokens}"
    );
}

/// `aobake key` gives the key `aobake bake` writes into the asset, for
/// every family, with clips from another file and parameters set by
/// `--param`, on `.gltf` files.
#[test]
fn key_is_the_baked_assets_key_for_every_family() {
    let dir = tempfile::tempdir().unwrap();
    let robot = repo().join("tests/data/scenes/RigidRobot/RigidRobot.gltf");
    let cube = repo().join("tests/data/scenes/SpinningCube/SpinningCube.gltf");
    let grid = [
        "grid.resolution=4",
        "grid.rays=8",
        "grid.eval_frames=1",
        "grid.eval_rays=8",
        "grid.eval_ground=8",
        "grid.average_frames=2",
    ];
    let cubemap = [
        "cubemap.resolution=4",
        "cubemap.times=8",
        "cubemap.rays=8",
        "cubemap.eval_times=1",
        "cubemap.eval_points=16",
        "cubemap.eval_ground=16",
        "cubemap.eval_rays=8",
    ];
    let cases: [(&Path, &str, &[&str]); 3] = [
        (&robot, "grid", &grid),
        (&cube, "cubemap-discrete", &cubemap),
        (&robot, "vertex-linear", &["samples=8"]),
    ];
    for (file, method, params) in cases {
        let mut args: Vec<String> = vec![
            file.display().to_string(),
            "--clips".into(),
            file.display().to_string(),
            "--method".into(),
            method.into(),
            "--poses".into(),
            "16".into(),
        ];
        for p in params {
            args.extend(["--param".into(), (*p).to_owned()]);
        }
        let run = |command: &str, extra: &[String]| {
            let out = Command::new(env!("CARGO_BIN_EXE_aobake"))
                .arg(command)
                .args(&args)
                .args(extra)
                .output()
                .unwrap();
            assert!(out.status.success(), "{command} {method}: {}", stderr(&out));
            out
        };
        let key = stdout(&run("key", &[]));
        let asset = dir.path().join(format!("{method}.aob"));
        run(
            "bake",
            &[
                "--out".into(),
                asset.display().to_string(),
                "--report".into(),
                dir.path()
                    .join(format!("{method}.json"))
                    .display()
                    .to_string(),
            ],
        );
        let bytes = std::fs::read(&asset).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        let baked = text
            .split("\"bake_key\":\"")
            .nth(1)
            .and_then(|s| s.get(..64))
            .unwrap();
        assert_eq!(key.trim(), baked, "{method}");
    }
}
