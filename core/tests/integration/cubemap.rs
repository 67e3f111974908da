//! Kroon's cubemaps as a bake: face jobs that resume from incremental
//! checkpoints with the same bytes, the whole graph in process on a real
//! character and on Kroon's spinning cube, both encodings judged against
//! ground truth they never saw.

use aobake_core::{
    asset::Container,
    bake::{Bake, BakeParams, JobError, JobSpec, NoSink, bake_in_process, cubemap::FaceInfo},
    bake::{BakeReport, cubemap::CubemapReport},
    method::{
        Method,
        cubemap::{ContinuousLayout, CubemapOptions, model::CubemapModel},
    },
};

use crate::{jobs::Interrupting, util};

/// A small cubemap bake: 16² texels, 4 shells, 32 time samples.
fn quick(method: Method) -> BakeParams {
    let mut p = BakeParams::new(method);
    p.cubemap = CubemapOptions {
        resolution: 16,
        shells: 4,
        times: 32,
        rays: 32,
        eval_times: 4,
        eval_points: 512,
        eval_ground: 256,
        eval_rays: 128,
        ..CubemapOptions::default()
    };
    p
}

fn cesium_man() -> aobake_core::Imported {
    util::load(&util::character_path("CesiumMan.glb").unwrap())
}

fn spinning_cube() -> aobake_core::Imported {
    util::load(&util::repo().join("tests/data/scenes/SpinningCube/SpinningCube.gltf"))
}

#[test]
fn a_face_job_resumed_from_its_parts_gives_the_same_bytes_and_saves_only_what_is_new() {
    let imported = cesium_man();
    let inputs = util::inputs(&imported.character, &imported.clips);
    let mut params = quick(Method::CubemapContinuous);
    params.cubemap.resolution = 8;
    params.cubemap.times = 16;
    let bake = Bake::new(&inputs, params).unwrap();
    let spec = JobSpec::Face { face: 3, times: 16 };
    let whole = bake.run_job(&spec, &[], None, &mut NoSink).unwrap();
    let info: FaceInfo = serde_json::from_slice(whole.get("face-3.json").unwrap()).unwrap();
    // 16 time samples: a checkpoint after each but the last.
    assert_eq!(
        (info.batch, info.checkpoints, info.computed, info.resumed_at),
        (1, 15, 16, 0)
    );
    let slice = 8 * 8 * 4;
    assert_eq!(info.part_bytes, 20 + slice);
    for stop_after in [1, 6, 15] {
        let mut first = Interrupting {
            stop_after: Some(stop_after),
            ..Default::default()
        };
        let err = bake.run_job(&spec, &[], None, &mut first).unwrap_err();
        assert!(matches!(err, JobError::Stopped(_)), "{err}");
        // Every checkpoint wrote one new part of one time slice, never the
        // field so far; its data is the small manifest.
        assert_eq!(first.part_sizes, vec![20 + slice; stop_after]);
        let last = first.saved.pop().unwrap();
        assert_eq!(
            (last.step.as_str(), last.cursor),
            ("face", stop_after as u64)
        );
        assert!(
            last.data.len() < 80 * stop_after + 20,
            "{}",
            last.data.len()
        );
        // The next attempt, given only the checkpoint and its parts,
        // computes the rest and ends with the same bytes.
        let mut next = Interrupting {
            parts: first.parts.clone(),
            ..Default::default()
        };
        let resumed = bake.run_job(&spec, &[], Some(last), &mut next).unwrap();
        assert_eq!(next.progress[0], (stop_after as u64, 16));
        assert_eq!(
            resumed.get("face-3"),
            whole.get("face-3"),
            "stopped after {stop_after}"
        );
        let info: FaceInfo = serde_json::from_slice(resumed.get("face-3.json").unwrap()).unwrap();
        assert_eq!(
            (info.computed, info.resumed_at),
            (16 - stop_after, stop_after)
        );
    }
    // A part that comes back altered is refused, not mixed in.
    let mut first = Interrupting {
        stop_after: Some(2),
        ..Default::default()
    };
    bake.run_job(&spec, &[], None, &mut first).unwrap_err();
    let last = first.saved.pop().unwrap();
    for bytes in first.parts.values_mut() {
        bytes[30] ^= 1;
    }
    let mut next = Interrupting {
        parts: first.parts,
        ..Default::default()
    };
    assert!(bake.run_job(&spec, &[], Some(last), &mut next).is_err());
}

fn report(baked: &aobake_core::bake::Baked) -> &CubemapReport {
    match &baked.report {
        BakeReport::Cubemap(r) => r,
        _ => panic!("a cubemap bake gave another report"),
    }
}

#[test]
fn both_encodings_bake_in_process_and_beat_the_static_cubemap_on_unseen_points() {
    for (name, imported) in [
        ("CesiumMan", cesium_man()),
        ("SpinningCube", spinning_cube()),
    ] {
        let inputs = util::inputs(&imported.character, &imported.clips);
        // Each bake's rows by name: another encoding's row in one bake is
        // that encoding as it would be baked.
        let mut reports = Vec::new();
        for (method, layout) in [
            (Method::CubemapDiscrete, ContinuousLayout::Cosine),
            (Method::CubemapContinuous, ContinuousLayout::Cosine),
            (Method::CubemapContinuous, ContinuousLayout::Thirds),
        ] {
            let mut params = quick(method);
            params.cubemap.continuous_layout = layout;
            let bake = Bake::new(&inputs, params).unwrap();
            let baked = bake_in_process(&bake, None).unwrap();
            let r = report(&baked);
            let container = Container::from_bytes(&baked.asset).unwrap();
            let (model, header) = CubemapModel::from_container(&container).unwrap();
            assert_eq!(header.method, method);
            assert_eq!(r.sizes.asset_bytes, baked.asset.len());
            // Four cubemaps either way: one per shell (4 shells here) or
            // the continuous encoding's four.
            assert_eq!(model.texels.len(), 4 * 6 * 16 * 16 * 16);
            assert_eq!(model.bytes(), model.texels.len() + 2 * 96 * 96);
            let v = &r.evaluation.variants;
            let names: Vec<&str> = v.iter().map(|v| v.name.as_str()).collect();
            let baked_name = match layout {
                ContinuousLayout::Thirds => "cubemap-continuous (thirds)",
                ContinuousLayout::Cosine => method.name(),
            };
            assert_eq!(names[0], baked_name, "the baked encoding first");
            for want in [
                "cubemap-discrete",
                "cubemap-continuous",
                "cubemap-continuous without residuals",
                "cubemap-continuous (thirds)",
                "uncompressed",
                "static (time average)",
            ] {
                assert!(names.contains(&want), "{names:?}");
            }
            let get = |n: &str| v.iter().find(|v| v.name == n).unwrap();
            let still = get("static (time average)");
            let baked_v = &v[0];
            eprintln!(
                "{name} {method} {layout:?}: space RMSE {:.4} (static {:.4}, uncompressed {:.4}), ground RMSE {:.4} (static {:.4}), noise {:.4}",
                baked_v.space.mean.rmse,
                still.space.mean.rmse,
                get("uncompressed").space.mean.rmse,
                baked_v.ground.mean.rmse,
                still.ground.mean.rmse,
                r.evaluation.ground_truth_noise_rmse
            );
            assert!(
                baked_v.space.mean.rmse < still.space.mean.rmse,
                "{name} {method}: the cubemap follows the motion better than its time average"
            );
            // On the ground, the baked cubemap's change on its static
            // ground texture beats both static baselines (the cubemap's
            // time average and the texture alone) and the cubemap alone.
            let ground = model.ground.as_ref().expect("a static ground by default");
            assert_eq!(ground.offsets.len(), 96 * 96);
            let bare = get(&format!("{baked_name} without the static ground"));
            let texture = get("static ground texture");
            eprintln!(
                "{name} {method} {layout:?}: on the ground {:.4}; without the static ground {:.4}, the texture alone {:.4}",
                baked_v.ground.mean.rmse, bare.ground.mean.rmse, texture.ground.mean.rmse
            );
            assert_eq!(bare.space, baked_v.space, "off the ground, the cubemap");
            for other in [still, bare, texture] {
                assert!(
                    baked_v.ground.mean.rmse < other.ground.mean.rmse,
                    "{name} {method}: on the ground, against {}",
                    other.name
                );
            }
            assert_eq!(r.charts.len(), 3);
            assert!(baked.plot.starts_with(b"\x89PNG"));
            reports.push(v.clone());
        }
        // Every encoding judged in another's bake (on a static ground
        // fitted to it, from the same truth) scores what its own bake
        // scores, off the ground and on it.
        for own in &reports {
            for other in &reports {
                let theirs = other.iter().find(|v| v.name == own[0].name).unwrap();
                assert_eq!(
                    (theirs.bytes, &theirs.space, &theirs.ground),
                    (own[0].bytes, &own[0].space, &own[0].ground),
                    "{name}: {} in {}'s bake",
                    own[0].name,
                    other[0].name
                );
            }
        }
    }
}

#[test]
fn residual_curves_cut_the_too_dark_error_as_in_the_thesis() {
    let imported = cesium_man();
    let inputs = util::inputs(&imported.character, &imported.clips);
    let bake = Bake::new(&inputs, quick(Method::CubemapContinuous)).unwrap();
    let baked = bake_in_process(&bake, None).unwrap();
    let v = &report(&baked).evaluation.variants;
    let get = |n: &str| v.iter().find(|v| v.name == n).unwrap();
    let with = get("cubemap-continuous");
    let without = get("cubemap-continuous without residuals");
    let (fw, fo) = (with.fit.unwrap(), without.fit.unwrap());
    eprintln!(
        "too dark: fit {:.6} vs {:.6}; space {:.6} vs {:.6}; ground {:.6} vs {:.6}",
        fw.too_dark_mse,
        fo.too_dark_mse,
        with.space.mean.too_dark_mse,
        without.space.mean.too_dark_mse,
        with.ground.mean.too_dark_mse,
        without.ground.mean.too_dark_mse
    );
    assert!(fw.too_dark_mse < fo.too_dark_mse);
    assert!(with.space.mean.too_dark_mse < without.space.mean.too_dark_mse);
}

#[test]
fn a_cubemap_bake_refuses_an_unknown_clip_and_options_by_name() {
    let imported = cesium_man();
    let inputs = util::inputs(&imported.character, &imported.clips);
    let mut p = quick(Method::CubemapDiscrete);
    p.cubemap.clip = Some("moonwalk".into());
    let e = Bake::new(&inputs, p).unwrap_err().to_string();
    assert!(e.contains("moonwalk") && e.contains("animation_0"), "{e}");
    let e = BakeParams::with_overrides(
        Method::CubemapDiscrete,
        serde_json::json!({"cubemap.times": 999})
            .as_object()
            .unwrap(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("cubemap.times"), "{e}");
}
