//! `aobake bake` and `aobake eval` as a user runs them.

use super::{aobake, occlusion_csv, sample, stderr};

fn run_bake(dir: &std::path::Path, name: &str, extra: &[&str]) -> std::process::Output {
    let figure = sample("RiggedFigure/RiggedFigure.glb");
    let out = dir.join(format!("{name}.aob"));
    let report = dir.join(format!("{name}.json"));
    let mut args = vec![
        "bake",
        figure.to_str().unwrap(),
        "--poses",
        "48",
        "--samples",
        "32",
        "--eval-poses",
        "4",
        "--eval-fps",
        "10",
        "--out",
        out.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    aobake(&args)
}

#[test]
fn bake_writes_a_deterministic_asset_a_report_and_a_plot() {
    let dir = tempfile::tempdir().unwrap();
    for (name, method) in [
        ("linear", "vertex-linear"),
        ("clustered", "vertex-clustered"),
        ("average", "static-average"),
    ] {
        let first = run_bake(dir.path(), name, &["--method", method]);
        assert!(first.status.success(), "{}", stderr(&first));
        let bytes = std::fs::read(dir.path().join(format!("{name}.aob"))).unwrap();
        assert_eq!(&bytes[..4], b"\x89AOB");
        let again = run_bake(dir.path(), &format!("{name}2"), &["--method", method]);
        assert!(again.status.success());
        let bytes2 = std::fs::read(dir.path().join(format!("{name}2.aob"))).unwrap();
        assert_eq!(
            bytes, bytes2,
            "{method}: the same command gives the same bytes"
        );

        let report: serde_json::Value = serde_json::from_slice(
            &std::fs::read(dir.path().join(format!("{name}.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(report["method"], method);
        assert_eq!(report["sizes"]["asset_bytes"], bytes.len());
        let clips = &report["evaluation"]["training_clip_frames"];
        for who in ["model", "baseline"] {
            for field in ["mae", "rmse", "psnr_db", "too_dark_mse", "too_bright_mse"] {
                assert!(clips[who]["mean"][field].is_number(), "{who}.{field}");
            }
        }
        assert_eq!(clips["model"]["frames"], 14, "1.25 s at 10 fps, both ends");
        let madds = report["evaluation"]["multiply_adds_per_vertex"]
            .as_f64()
            .unwrap();
        match method {
            // One per principal direction of the rotation-matrix
            // features (at most 1.5 per joint angle, no more than vary)
            // and one for the constant.
            "vertex-linear" => {
                let angles = report["character"]["joint_angle_parameters"]
                    .as_f64()
                    .unwrap();
                assert!(
                    madds > 1.0 && madds <= (1.5 * angles).round() + 1.0,
                    "{madds} for {angles} angles"
                );
            }
            "static-average" => assert_eq!(madds, 1.0),
            // The linear base (at most 1.5 per joint angle and its
            // constant), then n + 1 per pose cluster that MLS keeps.
            _ => {
                let angles = report["character"]["joint_angle_parameters"]
                    .as_f64()
                    .unwrap();
                let base = (1.5 * angles).round() + 1.0;
                assert!(
                    (2.0 + 11.0..=base + 10.0 * 11.0).contains(&madds),
                    "{madds}"
                );
            }
        }
        assert!(report["timings"]["reference_trace_s"].is_number());
        let noise = &report["ground_truth_noise"];
        assert_eq!(noise["frames"], 8);
        // 32 rays per vertex: visibly noisy, but far from random.
        let rmse = noise["rmse"].as_f64().unwrap();
        assert!(rmse > 0.001 && rmse < 0.1, "{noise}");
        if method != "static-average" {
            assert!(clips["psnr_gain_db"].as_f64().unwrap() > 0.0, "{report}");
        }
        let png = std::fs::read(dir.path().join(format!("{name}.png"))).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        assert!(stderr(&first).contains("frames of the training clips"));
    }
}

#[test]
fn the_summary_names_the_reference_rows_and_basis_cross_validation_chose() {
    // InterpolationTest has nine clips: `cv` (the default) chooses the
    // rows, and the summary and the report say which and why.
    let dir = tempfile::tempdir().unwrap();
    // Without --report, the report and its plot go beside the asset.
    let report = dir.path().join("r.report.json");
    let cubes = sample("InterpolationTest/InterpolationTest.glb");
    let out = aobake(&[
        "bake",
        cubes.to_str().unwrap(),
        "--method",
        "vertex-linear",
        "--poses",
        "96",
        "--samples",
        "32",
        "--eval-poses",
        "4",
        "--param",
        "eval_folds=0",
        "--out",
        dir.path().join("r.aob").to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.path().join("r.report.png").is_file());
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let choice = &report["fit"]["reference"];
    let scores = choice["scores"].as_array().unwrap();
    let names: Vec<&str> = scores.iter().map(|s| s[0].as_str().unwrap()).collect();
    assert_eq!(names, ["mixed", "perturbed", "all"]);
    let named = match choice["rows"].as_str().unwrap() {
        "mixed" => "reference rows: random poses and clip frames (",
        "perturbed" => "reference rows: clip frames and perturbed frames (",
        "all" => "reference rows: all three (",
        other => panic!("{other}"),
    };
    assert!(stderr(&out).contains(named), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("mean PSNR on left-out clips: random poses and clip frames "),
        "{}",
        stderr(&out)
    );
    // And the basis its cross-validation chose.
    let (basis, choice) = (&report["fit"]["basis"], &report["fit"]["basis_cv"]);
    let rank = choice["rank"].as_u64().unwrap();
    let threshold = choice["threshold"].as_f64().unwrap();
    assert_eq!(basis["rank"].as_u64(), Some(rank));
    assert_eq!(basis["threshold"].as_f64(), Some(threshold));
    let named = if threshold > 0.0 {
        format!(
            "{rank} rows, entries under 1/{} dropped (",
            (1.0 / threshold).round()
        )
    } else {
        format!("{rank} rows (")
    };
    let line = format!(
        "eigen-AO basis: {named}{:.1} multiply-adds a vertex), the cheapest of 160 candidates within 0.1 dB of the best on left-out clips (",
        basis["multiply_adds"].as_f64().unwrap()
    );
    assert!(stderr(&out).contains(&line), "{line}\n{}", stderr(&out));
}

#[test]
fn eval_gives_per_vertex_ao_at_a_pose() {
    let dir = tempfile::tempdir().unwrap();
    let baked = run_bake(dir.path(), "m", &["--method", "vertex-linear"]);
    assert!(baked.status.success(), "{}", stderr(&baked));
    let asset = dir.path().join("m.aob");
    let csv = dir.path().join("ao.csv");
    let figure = sample("RiggedFigure/RiggedFigure.glb");
    let eval = |time: &str| {
        let out = aobake(&[
            "eval",
            asset.to_str().unwrap(),
            figure.to_str().unwrap(),
            "--clip",
            "animation_0",
            "--time",
            time,
            "--out",
            csv.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
        let text = std::fs::read_to_string(&csv).unwrap();
        let values: Vec<f32> = text
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
            .collect();
        assert!(text.starts_with("index,occlusion\n"));
        values
    };
    let a = eval("0.2");
    assert_eq!(a.len(), 370);
    assert!(a.iter().all(|v| (0.0..=1.0).contains(v)));
    assert_ne!(a, eval("0.9"), "the pose changes the AO");
    // --rest: the nodes' rest transforms instead of the bind pose; it
    // takes no clip.
    let rest = |extra: &[&str]| {
        let mut args = vec![
            "eval",
            asset.to_str().unwrap(),
            figure.to_str().unwrap(),
            "--rest",
            "--out",
            csv.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        aobake(&args)
    };
    let out = rest(&[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let rows = std::fs::read_to_string(&csv).unwrap().lines().count();
    assert_eq!(rows, 371);
    let out = rest(&["--clip", "animation_0", "--time", "0.2"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
}

#[test]
fn eval_and_inspect_refuse_damaged_newer_and_foreign_assets() {
    let dir = tempfile::tempdir().unwrap();
    let baked = run_bake(dir.path(), "m", &["--method", "static-average"]);
    assert!(baked.status.success(), "{}", stderr(&baked));
    let good = std::fs::read(dir.path().join("m.aob")).unwrap();
    let bad = dir.path().join("bad.aob");
    let csv = dir.path().join("ao.csv");
    let eval = |asset: &std::path::Path, file: &str| {
        aobake(&[
            "eval",
            asset.to_str().unwrap(),
            sample(file).to_str().unwrap(),
            "--out",
            csv.to_str().unwrap(),
        ])
    };
    let mut damaged = good.clone();
    let last = damaged.len() - 9;
    damaged[last] ^= 0x40;
    std::fs::write(&bad, &damaged).unwrap();
    let out = eval(&bad, "RiggedFigure/RiggedFigure.glb");
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("checksum mismatch"),
        "{}",
        stderr(&out)
    );
    let out = aobake(&["inspect", bad.to_str().unwrap()]);
    assert!(!out.status.success(), "inspect checks every checksum");
    assert!(
        stderr(&out).contains("checksum mismatch in section COEF"),
        "{}",
        stderr(&out)
    );
    std::fs::write(&bad, &good[..good.len() - 100]).unwrap();
    let out = aobake(&["inspect", bad.to_str().unwrap()]);
    assert!(
        !out.status.success(),
        "a truncated asset is not a glTF file"
    );
    assert!(
        stderr(&out).contains("truncated") && !stderr(&out).contains("glTF"),
        "{}",
        stderr(&out)
    );

    let mut newer = good.clone();
    newer[8..10].copy_from_slice(&7u16.to_le_bytes());
    std::fs::write(&bad, &newer).unwrap();
    let out = eval(&bad, "RiggedFigure/RiggedFigure.glb");
    assert!(!out.status.success(), "a newer asset must fail");
    // The input is refused (aobake --help's exit codes).
    assert_eq!(out.status.code(), Some(5));
    assert!(
        stderr(&out).contains("asset format 7.")
            && stderr(&out).contains("is newer than this reader"),
        "{}",
        stderr(&out)
    );

    let out = eval(&dir.path().join("m.aob"), "RiggedSimple/RiggedSimple.glb");
    assert_eq!(
        out.status.code(),
        Some(5),
        "another character's asset is refused input"
    );
    assert!(
        stderr(&out).contains("baked for 370 vertices")
            && stderr(&out).contains("it was baked for another character upload"),
        "{}",
        stderr(&out)
    );

    // Refused input exits 5 (aobake --help), with what to do.
    let figure = sample("RiggedFigure/RiggedFigure.glb");
    let asset = dir.path().join("m.aob");
    let (figure, asset) = (figure.to_str().unwrap(), asset.to_str().unwrap());
    let missing = dir.path().join("absent.aob");
    let csv = csv.to_str().unwrap();
    for (args, says) in [
        (
            vec!["eval", missing.to_str().unwrap(), figure, "--out", csv],
            "cannot read ".to_owned() + missing.to_str().unwrap(),
        ),
        (
            vec![
                "eval", asset, figure, "--clip", "Dance", "--time", "0.1", "--out", csv,
            ],
            "no clip named \"Dance\"; the clips are: animation_0".to_owned(),
        ),
        // The arguments swapped: the character is not an asset, and the
        // error sees that the other one is.
        (
            vec!["eval", figure, asset, "--out", csv],
            format!(
                "not an aobake asset (bad magic bytes) ({asset} is one: the asset comes first, then the character)"
            ),
        ),
        (
            vec![
                "bake",
                "absent.glb",
                "--method",
                "static-average",
                "--out",
                asset,
            ],
            "cannot read absent.glb".to_owned(),
        ),
    ] {
        let out = aobake(&args);
        assert_eq!(out.status.code(), Some(5), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(&says), "{says:?} in {}", stderr(&out));
    }
}

/// A static prop (no skin, no animation) bakes in its one pose: its
/// static AO per vertex, darkest where it meets the floor; a method that
/// fits AO to poses is refused with what to use.
#[test]
fn a_static_prop_bakes_its_ao_as_modelled() {
    let dir = tempfile::tempdir().unwrap();
    let crates = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/data/props/Crates/Crates.glb");
    let crates = crates.to_str().unwrap();
    let asset = dir.path().join("c.aob");
    let csv = dir.path().join("c.csv");
    let out = aobake(&[
        "bake",
        crates,
        "--method",
        "static-average",
        "--poses",
        "8",
        "--samples",
        "64",
        "--out",
        asset.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("the character has no animation: it is baked as modelled"),
        "{}",
        stderr(&out)
    );
    let out = aobake(&[
        "eval",
        asset.to_str().unwrap(),
        crates,
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let ao: Vec<f32> = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    assert_eq!(ao.len(), 76);
    // The floor's far corners (0-3) are open; the big box's +z side
    // (vertices 12-15) is darker where it meets the floor (12, 13: half
    // its hemisphere is floor) than at its top (14, 15).
    assert!(ao[0..4].iter().all(|&a| a < 0.2), "{:?}", &ao[0..4]);
    let (foot, top) = ((ao[12] + ao[13]) / 2.0, (ao[14] + ao[15]) / 2.0);
    assert!(foot > 0.3 && foot > top + 0.2, "{:?}", &ao[12..16]);
    let out = aobake(&[
        "bake",
        crates,
        "--method",
        "vertex-linear",
        "--out",
        asset.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(5), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("vertex-linear fits AO to poses; bake static-average"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn bake_names_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_bake(
        dir.path(),
        "x",
        &["--method", "vertex-linear", "--train-clip", "Dance"],
    );
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("no clip named \"Dance\"; the clips are: animation_0"),
        "{}",
        stderr(&out)
    );
    let out = run_bake(
        dir.path(),
        "x",
        &["--method", "vertex-clustered", "--alpha", "-1"],
    );
    assert!(
        stderr(&out).contains("alpha must be in (0, 100]"),
        "{}",
        stderr(&out)
    );
    let skin = sample("SimpleSkin/SimpleSkin.gltf");
    let out = aobake(&["bake", skin.to_str().unwrap(), "--method", "vertex-linear"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("--out"), "{}", stderr(&out));
    // A clip file given twice, or the same bytes under two names, is
    // refused as the server refuses it (before anything is baked or sent).
    let rigged = sample("RiggedSimple/RiggedSimple.glb");
    let copy = dir.path().join("copy.glb");
    std::fs::copy(&rigged, &copy).unwrap();
    let (r, c) = (rigged.to_str().unwrap(), copy.to_str().unwrap());
    for (clips, says) in [
        ([r, r], format!("clip file {r} is given twice")),
        ([r, c], format!("clip files {r} and {c} are the same file")),
    ] {
        let out = aobake(&[
            "key",
            r,
            "--method",
            "vertex-linear",
            "--clips",
            clips[0],
            "--clips",
            clips[1],
        ]);
        assert_eq!(out.status.code(), Some(5), "{}", stderr(&out));
        assert!(stderr(&out).contains(&says), "{}", stderr(&out));
    }
    // Too many clip files are counted before any is read: 257 paths
    // that do not exist are refused for their number.
    let mut args = vec![
        "key".to_owned(),
        r.to_owned(),
        "--method".into(),
        "vertex-linear".into(),
    ];
    for n in 0..257 {
        args.push("--clips".into());
        args.push(
            dir.path()
                .join(format!("absent-{n}.glb"))
                .display()
                .to_string(),
        );
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = aobake(&args);
    assert_eq!(out.status.code(), Some(5), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("257 clip files, over the limit of 256"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn bench_bake_times_every_stage_and_each_step_of_the_fits() {
    // InterpolationTest's nine clips: a fit with cross-validation and
    // unseen-clip folds, each step its own line.
    let cubes = sample("InterpolationTest/InterpolationTest.glb");
    let out = aobake(&[
        "bench",
        "bake",
        cubes.to_str().unwrap(),
        "--method",
        "vertex-linear",
        "--poses",
        "48",
        "--samples",
        "16",
        "--eval-poses",
        "2",
        "--param",
        "eval_folds=2",
        "--threads",
        "2",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("2 threads"), "{stdout}");
    // (stage, jobs): every trace set, each fit step once, each fold's
    // steps twice (two folds).
    let jobs = |stage: &str| -> Option<usize> {
        stdout
            .lines()
            .find(|l| l.starts_with(&format!("| {stage} |")))
            .and_then(|l| l.split('|').nth(2))
            .and_then(|c| c.trim().parse().ok())
    };
    for stage in ["trace reference", "trace held-out", "trace noise"] {
        assert!(jobs(stage).is_some_and(|n| n > 0), "{stage}\n{stdout}");
    }
    for step in [
        "reference rows cv",
        "ridge cv and fit",
        "basis cv",
        "compress",
    ] {
        assert_eq!(jobs(&format!("fit: {step}")), Some(1), "{step}\n{stdout}");
        assert_eq!(
            jobs(&format!("unseen: {step}")),
            Some(2),
            "{step}\n{stdout}"
        );
    }
    assert_eq!(jobs("evaluate"), Some(1), "{stdout}");
    assert_eq!(jobs("assemble"), Some(1), "{stdout}");
    assert!(stdout.contains("| whole bake |"), "{stdout}");
    assert!(stdout.contains("MB |"), "peak memory\n{stdout}");
    assert!(stdout.contains("× the reference trace"), "{stdout}");
}

/// `aobake eval` reads an asset of every method: the vertex methods and
/// the grid give AO at every vertex of the posed character (the asset
/// stores only its method's own parameters, which eval once failed to
/// read for grids); a cubemap, which holds occlusion cast into space, is
/// refused with a message that says where to look instead.
#[test]
fn eval_and_inspect_read_an_asset_of_every_method() {
    let dir = tempfile::tempdir().unwrap();
    let truck = sample("CesiumMilkTruck/CesiumMilkTruck.glb");
    let rigged = sample("RiggedSimple/RiggedSimple.glb");
    let bake = |file: &std::path::Path, name: &str, args: &[&str]| {
        let out = dir.path().join(format!("{name}.aob"));
        let report = dir.path().join(format!("{name}.json"));
        let mut all = vec![
            "bake",
            file.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
        ];
        all.extend_from_slice(args);
        let run = aobake(&all);
        assert!(run.status.success(), "{name}: {}", stderr(&run));
        out
    };
    let quick = [
        "--poses",
        "24",
        "--samples",
        "16",
        "--eval-poses",
        "2",
        "--eval-fps",
        "5",
    ];
    let cases = [
        (
            bake(
                &rigged,
                "linear",
                &[&["--method", "vertex-linear"][..], &quick].concat(),
            ),
            &rigged,
            160,
        ),
        (
            bake(
                &rigged,
                "clustered",
                &[
                    &["--method", "vertex-clustered", "--pose-clusters", "2"][..],
                    &quick,
                ]
                .concat(),
            ),
            &rigged,
            160,
        ),
        (
            bake(
                &truck,
                "grid",
                &[
                    "--method",
                    "grid",
                    "--param",
                    r#"grid={"resolution":8,"rays":16,"eval_frames":1,"eval_ground":16,"eval_rays":8,"average_frames":1}"#,
                ],
            ),
            &truck,
            0,
        ),
    ];
    for (asset, file, vertices) in cases {
        let csv = dir.path().join("ao.csv");
        let out = aobake(&[
            "eval",
            asset.to_str().unwrap(),
            file.to_str().unwrap(),
            "--clip",
            "animation_0",
            "--time",
            "0.5",
            "--out",
            csv.to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{}: {}",
            asset.display(),
            stderr(&out)
        );
        let values = occlusion_csv(&csv);
        if vertices > 0 {
            assert_eq!(values.len(), vertices);
        }
        assert!(
            !values.is_empty() && values.iter().all(|v| (0.0..=1.0).contains(v)),
            "{}",
            asset.display()
        );
    }
    let cube = bake(
        &rigged,
        "cube",
        &[
            "--method",
            "cubemap-discrete",
            "--param",
            r#"cubemap={"resolution":8,"shells":2,"times":4,"rays":8,"eval_points":8,"eval_ground":8,"eval_rays":8,"eval_times":2}"#,
        ],
    );
    let out = aobake(&[
        "eval",
        cube.to_str().unwrap(),
        rigged.to_str().unwrap(),
        "--out",
        dir.path().join("c.csv").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("aobake preview"), "{}", stderr(&out));

    // `inspect` reads each asset whole, beside a character, and says what
    // the bake made.
    let assets =
        ["linear", "clustered", "grid", "cube"].map(|n| dir.path().join(format!("{n}.aob")));
    let mut args = vec!["inspect", "--json", rigged.to_str().unwrap()];
    args.extend(assets.iter().map(|a| a.to_str().unwrap()));
    let out = aobake(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    let reports: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(reports[0]["kind"], "character");
    assert_eq!(reports[0]["vertices"], 160);
    for (r, name) in
        reports.as_array().unwrap()[1..]
            .iter()
            .zip(["linear", "clustered", "grid", "cube"])
    {
        let report: serde_json::Value = serde_json::from_slice(
            &std::fs::read(dir.path().join(format!("{name}.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(r["kind"], "asset", "{name}");
        assert_eq!(r["header"]["bake_key"], report["bake_key"], "{name}");
        let bytes = std::fs::metadata(dir.path().join(format!("{name}.aob")))
            .unwrap()
            .len();
        assert_eq!(r["bytes"], bytes, "{name}");
        let tags: Vec<&str> = r["sections"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["tag"].as_str().unwrap())
            .collect();
        assert!(
            tags.contains(&"COEF") || tags.contains(&"RGBA") || tags.contains(&"TEXL"),
            "{name}: {tags:?}"
        );
    }
    let model = |i: usize| &reports[i]["model"];
    assert_eq!(reports[1]["method"], "vertex-linear");
    assert_eq!(model(1)["vertices"], 160);
    assert_eq!(
        model(1)["rig_named"],
        model(1)["rig_nodes"],
        "RiggedSimple names its nodes"
    );
    assert_eq!(reports[2]["method"], "vertex-clustered");
    assert!(
        model(2)["structure"]
            .as_str()
            .unwrap()
            .starts_with("2 pose clusters"),
        "{}",
        model(2)
    );
    assert_eq!(reports[3]["method"], "grid");
    assert_eq!(model(3)["cells_per_edge"], serde_json::json!([8, 8]));
    assert!(!model(3)["parts"].as_array().unwrap().is_empty());
    assert_eq!(reports[4]["method"], "cubemap-discrete");
    assert_eq!(model(4)["clip"], "animation_0");
    assert_eq!(
        (
            model(4)["resolution"].clone(),
            model(4)["shells"].clone(),
            model(4)["times"].clone()
        ),
        (8.into(), 2.into(), 4.into())
    );

    let out = aobake(&["inspect", assets[1].to_str().unwrap()]);
    let text = super::stdout(&out);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(text.contains("method       vertex-clustered"), "{text}");
    assert!(
        text.contains("checksums match and the model reads whole"),
        "{text}"
    );
    assert!(text.contains("rig          "), "{text}");
    // What an engine binds: the grid's palette entries, the cubemap's
    // spheroid.
    let out = aobake(&[
        "inspect",
        assets[2].to_str().unwrap(),
        assets[3].to_str().unwrap(),
    ]);
    let text = super::stdout(&out);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        text.contains("(palette entry 0)") && text.contains("palette      at least"),
        "{text}"
    );
    assert!(text.contains("spheroid     centre ["), "{text}");
}

#[test]
fn the_free_tracer_is_reported_as_work_besides_tracing_not_as_a_speed() {
    let fox = sample("Fox/Fox.glb");
    let out = aobake(&[
        "bench",
        "grid",
        fox.to_str().unwrap(),
        "--resolution",
        "8",
        "--rays",
        "16",
        "--repeat",
        "1",
        "--tracer",
        "free,cpu",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    // Compared with the tracer that casts rays, whatever the order given.
    assert!(
        stdout.contains("grid slab: its work besides tracing (no rays cast) takes"),
        "{stdout}"
    );
    assert!(stdout.contains("run 1 (free): no rays cast"), "{stdout}");
    for nonsense in ["free traces", "free:", "cells free against"] {
        assert!(!stdout.contains(nonsense), "{nonsense}\n{stdout}");
    }
    let alone = aobake(&["bench", "grid", fox.to_str().unwrap(), "--tracer", "free"]);
    assert!(!alone.status.success());
    assert!(stderr(&alone).contains("casts rays"), "{}", stderr(&alone));
}

#[test]
fn a_cubemap_previews_only_the_clip_it_was_baked_over() {
    let dir = tempfile::tempdir().unwrap();
    let fox = sample("Fox/Fox.glb");
    let asset = dir.path().join("walk.aob");
    let out = aobake(&[
        "bake",
        fox.to_str().unwrap(),
        "--method",
        "cubemap-discrete",
        "--param",
        r#"cubemap={"clip":"Walk","resolution":4,"shells":2,"times":4,"rays":4,"eval_points":8,"eval_ground":8,"eval_rays":4,"eval_times":2,"ground_resolution":8}"#,
        "--out",
        asset.to_str().unwrap(),
        "--report",
        dir.path().join("walk.json").to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let png = dir.path().join("p.png");
    let out = aobake(&[
        "preview",
        asset.to_str().unwrap(),
        fox.to_str().unwrap(),
        "--clip",
        "Survey",
        "--time",
        "0.3",
        "--out",
        png.to_str().unwrap(),
    ]);
    assert!(!out.status.success(), "Walk's cubemaps shown under Survey");
    assert!(
        stderr(&out).contains("cubemaps of clip \"Walk\"")
            && stderr(&out).contains("--clip \"Walk\""),
        "{}",
        stderr(&out)
    );
    assert!(!png.exists());
}
