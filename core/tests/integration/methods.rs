//! The vertex methods end to end on real characters: reference poses
//! traced, fitted, judged on held-out poses against the static average,
//! written as assets and read back.

use aobake_core::{
    Character, Clip, Pose,
    asset::{AssetError, Container},
    bake::{Bake, BakeParams, Evaluation, Plan, bake_in_process},
    method::{
        Method,
        vertex::{FormRef, Model, VertexAo},
    },
    pose_space,
};

use crate::util;

struct Baked {
    model: Model,
    evaluation: Evaluation,
    bytes: Vec<u8>,
}

/// The whole bake in process: what `aobake bake` and the service's jobs do.
fn bake(character: &Character, clips: &[Clip], params: BakeParams) -> Baked {
    let inputs = util::inputs(character, clips);
    let baked = bake_in_process(&Bake::new(&inputs, params).unwrap(), None).unwrap();
    let container = Container::from_bytes(&baked.asset).unwrap();
    Baked {
        model: Model::from_container(&container).unwrap().0,
        evaluation: baked.report.vertex().unwrap().evaluation.clone(),
        bytes: baked.asset,
    }
}

fn quick(method: Method) -> BakeParams {
    let mut p = BakeParams::new(method);
    p.poses = 96;
    p.samples = 64;
    p.eval_poses = 8;
    p.eval_fps = 15.0;
    p
}

/// Model and baseline on held-out clip frames: the model must have the
/// higher mean PSNR and the lower mean MAE.
fn assert_beats_baseline(name: &str, method: Method, e: &Evaluation) {
    let c = &e.training_clip_frames;
    eprintln!(
        "{name} {}: {:.2} dB vs {:.2} dB ({:+.2} dB), MAE {:.4} vs {:.4} (×{:.2}), {} frames",
        method.name(),
        c.model.mean.psnr_db,
        c.baseline.mean.psnr_db,
        c.psnr_gain_db,
        c.model.mean.mae,
        c.baseline.mean.mae,
        c.mae_ratio,
        c.model.frames
    );
    assert!(c.model.frames > 0);
    assert!(c.psnr_gain_db > 0.0, "{name} {method:?}: {c:?}");
    assert!(c.mae_ratio < 1.0, "{name} {method:?}: {c:?}");
}

#[test]
fn methods_beat_the_static_average_on_held_out_clip_frames() {
    // The bundled characters always; every shared one with clips when
    // ../shared/data is there.
    for path in util::all_characters() {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let imported = util::load(&path);
        if imported.clips.is_empty() {
            continue;
        }
        for method in [Method::VertexLinear, Method::VertexClustered] {
            let baked = bake(&imported.character, &imported.clips, quick(method));
            let base = &baked.evaluation.training_clip_frames.baseline.mean;
            if base.mae < 1e-6 {
                // SimpleSkin's strip never occludes itself: AO is 0 in
                // every pose and nothing can beat an exact baseline; the
                // model must be exact too.
                assert!(
                    baked.evaluation.training_clip_frames.model.mean.mae < 1e-6,
                    "{name}"
                );
                continue;
            }
            assert_beats_baseline(&name, method, &baked.evaluation);
        }
    }
}

#[test]
fn fox_generalises_to_a_clip_it_never_saw() {
    // Kirk & Arikan's test: train on two clips, test on the third. Run
    // leaves the joint-angle ranges of Survey and Walk, so half the
    // reference poses are random joint angles in those ranges (the default
    // for vertex-linear; vertex-clustered trained on clip frames alone
    // gains only a few tenths of a dB here).
    let imported = util::load(&util::character_path("Fox.glb").unwrap());
    for method in [Method::VertexLinear, Method::VertexClustered] {
        let mut p = quick(method);
        p.reference = aobake_core::bake::ReferenceSource::Mixed;
        p.poses = 160;
        p.train_clips = vec!["Survey".into(), "Walk".into()];
        p.test_clips = vec!["Run".into()];
        let baked = bake(&imported.character, &imported.clips, p);
        assert_eq!(baked.evaluation.clips.len(), 1);
        assert_eq!(baked.evaluation.clips[0].clip, "Run");
        assert_beats_baseline("Fox (Run held out)", method, &baked.evaluation);
    }
}

#[test]
fn bakes_are_deterministic_and_assets_round_trip() {
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let c = &imported.character;
    let mut variants = vec![quick(Method::StaticAverage), quick(Method::VertexLinear)];
    // Without the eigen-AO basis, dense and sparse.
    let mut full = quick(Method::VertexLinear);
    full.linear.basis = 0;
    variants.push(full.clone());
    let mut sparse = full;
    sparse.linear.threshold = 0.005;
    variants.push(sparse);
    // A basis small enough to be used on this small rig.
    let mut small_basis = quick(Method::VertexLinear);
    small_basis.linear.basis = 4;
    variants.push(small_basis);
    variants.push(quick(Method::VertexClustered));
    let mut compressed = quick(Method::VertexClustered);
    compressed.clustered.vertex_clusters = 50;
    compressed.clustered.basis = 0;
    variants.push(compressed);
    // Kirk & Arikan's own: the clusters on the mean, no linear base, no
    // basis.
    let mut paper = quick(Method::VertexClustered);
    paper.clustered.base = aobake_core::method::vertex::Base::Mean;
    paper.clustered.basis = 0;
    variants.push(paper);
    for params in variants {
        let a = bake(c, &imported.clips, params.clone());
        let b = bake(c, &imported.clips, params.clone());
        let basis = match &a.model {
            Model::VertexLinear(_, m) => m.basis.as_ref(),
            Model::VertexClustered(_, m) => m.basis.as_ref(),
            Model::StaticAverage(_) => None,
        };
        let asked = match params.method {
            Method::VertexLinear => params.linear.basis,
            Method::VertexClustered => params.clustered.basis,
            _ => 0,
        };
        if asked == 4 {
            assert_eq!(basis.map(|b| b.rank), Some(4), "{params:?}");
        } else if asked == 0 {
            assert!(basis.is_none());
        }
        assert_eq!(a.bytes, b.bytes, "{params:?}: same request, same bytes");
        let container = Container::from_bytes(&a.bytes).unwrap();
        assert_eq!(container.method, params.method);
        let (back, header) = Model::from_container(&container).unwrap();
        assert_eq!(back, a.model, "{:?}", params.method);
        assert_eq!(header.vertices, c.vertex_count());
        assert_eq!(header.bake_key.len(), 64);
        let pose = Pose::sample(&c.skeleton, &imported.clips[0], 0.4);
        let expected = a.model.evaluate(&c.skeleton, &pose.locals);
        assert_eq!(back.evaluate(&c.skeleton, &pose.locals), expected);
        // As an engine plays it: the asset alone, its rig, each animated
        // node's local transform set by name; bit for bit the same.
        let mut engine = VertexAo::from_bytes(&a.bytes).unwrap();
        assert_eq!(
            engine.evaluate(),
            a.model.evaluate(&c.skeleton, &c.skeleton.rest_locals())
        );
        for (n, local) in pose.locals.iter().enumerate() {
            let name = c.skeleton.nodes[n]
                .name
                .as_deref()
                .expect("RiggedFigure names its nodes");
            let node = engine.node(name).expect("the rig has every node");
            assert!(engine.set_local(node, *local));
        }
        assert_eq!(engine.evaluate(), expected, "{:?}", params.method);
        // Another seed, other bytes.
        let mut other = params;
        other.seed = 9;
        assert_ne!(bake(c, &imported.clips, other).bytes, a.bytes);
    }
}

#[test]
fn a_rig_that_does_not_fit_is_refused_and_an_asset_without_one_is_named() {
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let baked = bake(
        &imported.character,
        &imported.clips,
        quick(Method::VertexLinear),
    );
    let container = Container::from_bytes(&baked.bytes).unwrap();
    let mut header: serde_json::Value = serde_json::from_str(&container.header).unwrap();
    let reread = |header: &serde_json::Value| {
        let mut c = container.clone();
        c.header = header.to_string();
        Container::from_bytes(&c.to_bytes()).unwrap()
    };
    // A node that is its own parent: the order no longer has parents first.
    let mut cycle = header.clone();
    cycle["rig"]["nodes"][1]["parent"] = 1.into();
    assert!(matches!(
        Model::from_container(&reread(&cycle)),
        Err(AssetError::Malformed(m)) if m.contains("parent")
    ));
    // A layout that reads a node past the rig's end.
    let mut short = header.clone();
    let nodes = short["rig"]["nodes"].as_array().unwrap().len();
    short["layout"]["joint_angles"]["joints"][0] = (nodes + 5).into();
    assert!(matches!(
        Model::from_container(&reread(&short)),
        Err(AssetError::Malformed(m)) if m.contains("does not fit the rig")
    ));
    // Written before format 1.4: the model reads, an engine cannot pose it
    // by name and is told why.
    header.as_object_mut().unwrap().remove("rig");
    let old = reread(&header);
    assert!(Model::from_container(&old).is_ok());
    assert!(matches!(
        VertexAo::from_bytes(&old.to_bytes()),
        Err(AssetError::Unsupported(m)) if m.contains("no rig")
    ));
}

#[test]
fn a_model_whose_header_disagrees_with_its_sections_is_refused() {
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let baked = bake(
        &imported.character,
        &imported.clips,
        quick(Method::VertexClustered),
    );
    let mut container = Container::from_bytes(&baked.bytes).unwrap();
    container.header = container
        .header
        .replacen("\"vertices\":370", "\"vertices\":371", 1);
    let reread = Container::from_bytes(&container.to_bytes()).unwrap();
    // The primitive table no longer tiles the vertices.
    assert!(matches!(
        Model::from_container(&reread),
        Err(AssetError::Malformed(m)) if m.contains("the primitives cover 370 of the asset's 371 vertices")
    ));
    // Without one (a file before format 1.6), the sections do not fit.
    let mut header: serde_json::Value = serde_json::from_str(&container.header).unwrap();
    header
        .as_object_mut()
        .unwrap()
        .remove("primitives")
        .unwrap();
    container.header = header.to_string();
    let reread = Container::from_bytes(&container.to_bytes()).unwrap();
    assert!(matches!(
        Model::from_container(&reread),
        Err(AssetError::Malformed(m)) if m.contains("COEF length")
    ));
}

#[test]
fn bad_parameters_are_named() {
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let c = &imported.character;
    let mut p = quick(Method::VertexLinear);
    p.train_clips = vec!["Dance".into()];
    let err = Plan::new(c, &imported.clips, p).unwrap_err().to_string();
    assert!(
        err.contains("no clip named \"Dance\"") && err.contains("animation_0"),
        "{err}"
    );
    let mut p = quick(Method::VertexClustered);
    p.clustered.alpha = f32::NAN;
    let err = Plan::new(c, &imported.clips, p).unwrap_err().to_string();
    assert!(err.contains("alpha"), "{err}");
    let mut p = quick(Method::VertexLinear);
    p.poses = 0;
    assert!(
        Plan::new(c, &imported.clips, p)
            .unwrap_err()
            .to_string()
            .contains("poses")
    );
    let err = Plan::new(c, &[], quick(Method::VertexLinear))
        .unwrap_err()
        .to_string();
    assert!(err.contains("no clips"), "{err}");
}

/// A change to an asset's JSON header.
type Edit = Box<dyn Fn(&mut serde_json::Value)>;

/// A file that passes every checksum but was written to hurt: its header
/// edited and the file re-sealed. Each must be refused with an error, never
/// a panic or NaN.
#[test]
fn hostile_assets_with_valid_checksums_are_refused() {
    use serde_json::{Value, json};
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let c = &imported.character;
    let mut linear_params = quick(Method::VertexLinear);
    linear_params.linear.basis_cv = false;
    let linear = bake(c, &imported.clips, linear_params).bytes;
    let mut clustered_params = quick(Method::VertexClustered);
    clustered_params.clustered.vertex_clusters = 30;
    clustered_params.clustered.basis = 0;
    let clustered = bake(c, &imported.clips, clustered_params).bytes;

    let edit = |bytes: &[u8], f: &dyn Fn(&mut Value)| -> Result<Model, AssetError> {
        let mut container = Container::from_bytes(bytes).unwrap();
        let mut header: Value = serde_json::from_str(&container.header).unwrap();
        f(&mut header);
        container.header = header.to_string();
        let resealed = Container::from_bytes(&container.to_bytes())?;
        Model::from_container(&resealed).map(|(m, _)| m)
    };
    let linear_edits: Vec<(&str, Edit)> = vec![
        ("no vertices", Box::new(|h| h["vertices"] = json!(0))),
        (
            "huge vertices",
            Box::new(|h| h["vertices"] = json!(u64::MAX)),
        ),
        (
            "names without joints",
            Box::new(|h| h["layout"]["joint_angles"]["names"] = json!([])),
        ),
        (
            "reversed range",
            Box::new(|h| {
                h["layout"]["joint_angles"]["ranges"][0] = json!({"min": 1.0, "max": -1.0})
            }),
        ),
        (
            "infinite range",
            Box::new(|h| h["layout"]["joint_angles"]["ranges"][0]["max"] = json!(1e39)),
        ),
        (
            "sparse claimed",
            Box::new(|h| h["layout"]["sparse"] = json!(true)),
        ),
        (
            "method swapped",
            Box::new(|h| h["method"] = json!("static-average")),
        ),
    ];
    for (what, f) in &linear_edits {
        assert!(edit(&linear, f.as_ref()).is_err(), "linear: {what}");
    }
    let clustered_edits: Vec<(&str, Edit)> = vec![
        (
            "huge dimensions",
            Box::new(|h| h["layout"]["dimensions"] = json!(1u64 << 62)),
        ),
        (
            "zero dimensions",
            Box::new(|h| h["layout"]["dimensions"] = json!(0)),
        ),
        (
            "no clusters",
            Box::new(|h| h["layout"]["columns"] = json!([])),
        ),
        (
            "alpha overflow",
            Box::new(|h| h["layout"]["alpha"] = json!(1e39)),
        ),
        (
            "negative clamp",
            Box::new(|h| h["layout"]["clamp"] = json!(-1.0)),
        ),
        (
            "offsets missing",
            Box::new(|h| h["layout"]["handles"]["offsets"] = json!([])),
        ),
        (
            "more columns than vertices",
            Box::new(|h| h["layout"]["columns"][0] = json!(100_000)),
        ),
        (
            "unmapped columns",
            Box::new(|h| h["layout"]["columns"][0] = json!(370)),
        ),
        (
            "sparse without a basis",
            Box::new(|h| h["layout"]["sparse"] = json!(true)),
        ),
    ];
    for (what, f) in &clustered_edits {
        assert!(edit(&clustered, f.as_ref()).is_err(), "clustered: {what}");
    }
    // A NaN coefficient, sealed with a fresh checksum.
    let mut container = Container::from_bytes(&linear).unwrap();
    for s in &mut container.sections {
        if let aobake_core::asset::Data::F16(v) = &mut s.data {
            v[3] = half::f16::NAN;
        }
    }
    let err = Model::from_container(&Container::from_bytes(&container.to_bytes()).unwrap());
    assert!(matches!(err, Err(AssetError::Malformed(m)) if m.contains("finite")));
    // Unedited, both read back.
    assert!(edit(&linear, &|_| {}).is_ok() && edit(&clustered, &|_| {}).is_ok());
    // Eigen-AO bases whose header disagrees with BMIX and COEF.
    let mut p = quick(Method::VertexLinear);
    (p.linear.basis, p.linear.basis_cv) = (4, false);
    let linear = bake(c, &imported.clips, p.clone()).bytes;
    p.linear.basis_threshold = 1.0 / 512.0;
    let sparse_linear = bake(c, &imported.clips, p).bytes;
    let mut p = quick(Method::VertexClustered);
    (p.clustered.basis, p.clustered.basis_cv) = (4, false);
    let clustered = bake(c, &imported.clips, p.clone()).bytes;
    p.clustered.basis_threshold = 1.0 / 512.0;
    let sparse_clustered = bake(c, &imported.clips, p).bytes;
    let basis_edits: Vec<(&str, Edit)> = vec![
        ("basis grown", Box::new(|h| h["layout"]["basis"] = json!(5))),
        (
            "basis shrunk",
            Box::new(|h| h["layout"]["basis"] = json!(3)),
        ),
        (
            "huge basis",
            Box::new(|h| h["layout"]["basis"] = json!(1u64 << 40)),
        ),
        (
            "basis dropped",
            Box::new(|h| h["layout"]["basis"] = json!(0)),
        ),
    ];
    let bases = [
        ("linear", &linear),
        ("clustered", &clustered),
        ("sparse linear", &sparse_linear),
        ("sparse clustered", &sparse_clustered),
    ];
    for (what, f) in &basis_edits {
        for (name, bytes) in bases {
            assert!(
                matches!(edit(bytes, f.as_ref()), Err(AssetError::Malformed(_))),
                "{name}: {what}"
            );
        }
    }
    // Dense rows claimed sparse, and sparse ones claimed dense.
    for (name, bytes) in bases {
        let sparse = name.starts_with("sparse");
        assert!(
            edit(bytes, &|h| h["layout"]["sparse"] = json!(!sparse)).is_err(),
            "{name}: sparse flipped"
        );
        let model = edit(bytes, &|_| {}).unwrap();
        assert_eq!(matches!(model.form(), FormRef::Sparse(_)), sparse, "{name}");
    }
    assert!(
        edit(&clustered, &|h| h["layout"]["columns"][0] = json!(100)).is_err(),
        "vertex clusters under a basis"
    );
    assert!(edit(&linear, &|_| {}).is_ok() && edit(&clustered, &|_| {}).is_ok());
    // A sparse basis's rows point past the basis: refused.
    let mut container = Container::from_bytes(&sparse_clustered).unwrap();
    for s in &mut container.sections {
        if s.tag == *b"CSRR"
            && let aobake_core::asset::Data::U16(rows) = &mut s.data
        {
            rows[0] = 5;
        }
    }
    let err = Model::from_container(&Container::from_bytes(&container.to_bytes()).unwrap());
    assert!(matches!(err, Err(AssetError::Malformed(m)) if m.contains("sparse")));
}

#[test]
fn cross_validation_over_clips_chooses_the_reference_rows() {
    // `reference = cv` traces random poses, clip frames and perturbed clip
    // frames, a third each; the fit uses the rows that score best on the
    // clips its cross-validation leaves out. The same seeds draw the same
    // poses for `mixed` and `perturbed` with two thirds as many, so the
    // chosen model is, bit for bit, the one those bakes fit.
    use aobake_core::{
        bake::ReferenceSource,
        method::vertex::{FitStats, Rows},
    };
    let mut chosen = Vec::new();
    for name in ["InterpolationTest.glb", "Fox.glb"] {
        let imported = util::load(&util::character_path(name).unwrap());
        let mut params = quick(Method::VertexLinear);
        params.eval_folds = 0;
        params.poses = 384;
        assert_eq!(params.reference, ReferenceSource::Cv, "the default");
        let inputs = util::inputs(&imported.character, &imported.clips);
        let report = bake_in_process(&Bake::new(&inputs, params.clone()).unwrap(), None)
            .unwrap()
            .report;
        let FitStats::VertexLinear(stats) = &report.vertex().unwrap().fit else {
            panic!("{name}: a vertex-linear fit");
        };
        let choice = stats.reference.clone().expect("a choice");
        eprintln!("{name}: {choice:?}");
        let best = choice
            .scores
            .iter()
            .map(|s| s.1)
            .fold(f64::NEG_INFINITY, f64::max);
        assert_eq!(choice.scores.len(), 3);
        assert!(choice.scores.iter().all(|s| s.1.is_finite()));
        assert_eq!(
            choice.scores.iter().find(|s| s.0 == choice.rows).unwrap().1,
            best
        );
        let model = bake(&imported.character, &imported.clips, params.clone()).model;
        let alone = match choice.rows {
            Rows::Mixed => Some(ReferenceSource::Mixed),
            Rows::Perturbed => Some(ReferenceSource::Perturbed),
            Rows::All => None,
        };
        if let Some(reference) = alone {
            let mut p = params.clone();
            p.reference = reference;
            p.poses = 256;
            let other = bake(&imported.character, &imported.clips, p).model;
            assert!(model == other, "{name}: the {reference:?} rows alone");
        }
        chosen.push(choice.rows);
    }
    // Cubes scaled, turned and moved one at a time gain from perturbed
    // frames; the fox needs random poses (here all three rows, with the
    // default 2048 poses random poses and frames; perturbed frames alone
    // score over a dB worse).
    assert_eq!(chosen[0], Rows::Perturbed);
    assert_ne!(chosen[1], Rows::Perturbed);
}

#[test]
fn cross_validation_over_clips_chooses_the_basis() {
    // With `basis_cv` (the default) the fit keeps the cheapest eigen-AO
    // basis (rows, and a threshold below which entries are dropped) whose
    // left-out clips score within a tenth of a decibel of the best
    // candidate's: the model is, bit for bit, the one a bake asking for
    // that basis fits, and costs a vertex what the choice says.
    use aobake_core::method::vertex::{
        BasisChoice, Coefficients,
        cv::{BASIS_THRESHOLDS, BASIS_TOLERANCE_DB},
    };
    let imported = util::load(&util::character_path("InterpolationTest.glb").unwrap());
    for method in [Method::VertexLinear, Method::VertexClustered] {
        let mut params = quick(method);
        params.eval_folds = 0;
        params.poses = 192;
        assert!(
            params.linear.basis_cv && params.clustered.basis_cv,
            "the default"
        );
        let inputs = util::inputs(&imported.character, &imported.clips);
        let baked = bake_in_process(&Bake::new(&inputs, params.clone()).unwrap(), None).unwrap();
        let report = baked.report.vertex().unwrap();
        let fit = &report.fit;
        let choice: &BasisChoice = fit.basis_cv().expect("a choice");
        let chosen = *choice.chosen().unwrap();
        eprintln!("{method}: {chosen:?}; best {:?}", choice.best().unwrap());
        // Every rank from 1 to 32 at every threshold.
        assert_eq!(choice.candidates.len(), 32 * BASIS_THRESHOLDS.len());
        for (k, c) in choice.candidates.iter().enumerate() {
            assert_eq!(
                (c.rank, c.threshold),
                (k % 32 + 1, BASIS_THRESHOLDS[k / 32])
            );
            assert!(c.psnr_db.is_finite() && c.multiply_adds >= 1.0);
        }
        let best = choice.best().unwrap().psnr_db;
        let cheapest = choice
            .candidates
            .iter()
            .filter(|c| c.psnr_db >= best - BASIS_TOLERANCE_DB)
            .map(|c| c.multiply_adds)
            .fold(f64::INFINITY, f64::min);
        assert_eq!(chosen.multiply_adds, cheapest);
        // The cubes cost a vertex fewer multiply-adds than 32 dense rows.
        assert!(chosen.multiply_adds < 20.0, "{method}: {chosen:?}");
        let basis = fit.basis().unwrap();
        assert_eq!(
            (basis.rank, basis.threshold),
            (chosen.rank, chosen.threshold)
        );
        assert!((report.evaluation.multiply_adds_per_vertex - chosen.multiply_adds).abs() < 1e-9);
        let model = Model::from_container(&Container::from_bytes(&baked.asset).unwrap())
            .unwrap()
            .0;
        let sparse = match &model {
            Model::VertexLinear(_, m) => matches!(m.coefficients, Coefficients::Sparse(_)),
            Model::VertexClustered(_, m) => matches!(m.form, Coefficients::Sparse(_)),
            Model::StaticAverage(_) => unreachable!(),
        };
        assert_eq!(sparse, chosen.threshold > 0.0);
        let mut fixed = params.clone();
        (fixed.linear.basis, fixed.linear.basis_threshold) = (chosen.rank, chosen.threshold);
        (fixed.clustered.basis, fixed.clustered.basis_threshold) = (chosen.rank, chosen.threshold);
        (fixed.linear.basis_cv, fixed.clustered.basis_cv) = (false, false);
        let other = bake(&imported.character, &imported.clips, fixed);
        assert!(model == other.model, "{method}: {chosen:?} asked for");
    }
}

#[test]
fn the_report_measures_clips_the_model_never_saw() {
    use aobake_core::bake::Plan;
    let imported = util::load(&util::character_path("Fox.glb").unwrap());
    let params = quick(Method::VertexLinear);
    let plan = Plan::new(&imported.character, &imported.clips, params.clone()).unwrap();
    // The default reference poses (`cv`): random ones first, then clip
    // frames, then perturbed clip frames, a third each; the static average
    // is fitted to the plain clip frames alone.
    let sources = plan.reference_sources();
    assert_eq!(sources.len(), 96);
    use aobake_core::method::vertex::Source;
    assert!(sources[..32].iter().all(|s| *s == Source::Random));
    assert!(
        sources[32..64]
            .iter()
            .all(|s| matches!(s, Source::Frame(_)))
    );
    assert!(
        sources[64..]
            .iter()
            .all(|s| matches!(s, Source::Perturbed(_)))
    );
    assert_eq!(plan.baseline_rows(), (32..64).collect::<Vec<_>>());
    let baked = bake(&imported.character, &imported.clips, params);
    let unseen = baked
        .evaluation
        .unseen_clips
        .as_ref()
        .expect("three clips, three folds");
    let names: Vec<&str> = unseen.folds.iter().map(|f| f.clip.as_str()).collect();
    assert_eq!(names, ["Survey", "Walk", "Run"]);
    for (k, fold) in unseen.folds.iter().enumerate() {
        // Refitted without a single reference pose of its clip, judged on
        // every held-out frame of that clip.
        let from_clip = sources.iter().filter(|s| s.clip() == Some(k)).count();
        assert!(from_clip > 0);
        assert_eq!(fold.reference_poses, 96 - from_clip);
        // Two clips left: the fold's own cross-validation chose its rows.
        assert!(fold.rows.is_some(), "{fold:?}");
        let frames = baked
            .evaluation
            .clips
            .iter()
            .find(|c| c.clip == fold.clip)
            .unwrap()
            .times
            .len();
        assert_eq!(fold.errors.model.frames, frames);
        eprintln!(
            "Fox without {}: {:.2} dB against {:.2} dB ({:+.2} dB)",
            fold.clip,
            fold.errors.model.mean.psnr_db,
            fold.errors.baseline.mean.psnr_db,
            fold.errors.psnr_gain_db
        );
    }
    let mean = unseen
        .folds
        .iter()
        .map(|f| f.errors.psnr_gain_db)
        .sum::<f64>()
        / 3.0;
    assert!((unseen.mean_psnr_gain_db - mean).abs() < 1e-9);
    // One clip: nothing to leave out.
    let cesium = util::load(&util::character_path("CesiumMan.glb").unwrap());
    let one = bake(
        &cesium.character,
        &cesium.clips,
        quick(Method::VertexLinear),
    );
    assert!(one.evaluation.unseen_clips.is_none());
}

#[test]
fn a_local_linear_model_uses_only_the_joints_near_each_vertex() {
    use aobake_core::method::vertex::{Features, Locality};
    let imported = util::load(&util::character_path("Fox.glb").unwrap());
    let c = &imported.character;
    let plan =
        aobake_core::bake::Plan::new(c, &imported.clips, quick(Method::VertexLinear)).unwrap();
    let sets = pose_space::local_parameters(&plan.joint_angles, c);
    let n = plan.joint_angles.len();
    assert_eq!(sets.len(), c.vertex_count());
    let mean = sets.iter().map(Vec::len).sum::<usize>() as f64 / sets.len() as f64;
    assert!(mean > 0.0 && mean < 0.5 * n as f64, "{mean} of {n}");
    // Locality is measured on rotation vectors (with matrix features, the
    // default, the cross-validation over clips prefers the global model
    // on Fox).
    let mut local = quick(Method::VertexLinear);
    local.linear.features = Features::RotationVector;
    local.linear.locality = Locality::On;
    // The models as fitted: an eigen-AO basis would compress the global
    // one too.
    local.linear.basis = 0;
    let mut global = local.clone();
    global.linear.locality = Locality::Off;
    let (l, g) = (
        bake(c, &imported.clips, local),
        bake(c, &imported.clips, global),
    );
    // Fewer coefficients, fewer multiply-adds, and still better than the
    // static average on the training clips' frames.
    assert!(l.bytes.len() < g.bytes.len());
    assert!(
        l.evaluation.multiply_adds_per_vertex < 0.5 * g.evaluation.multiply_adds_per_vertex,
        "{} against {}",
        l.evaluation.multiply_adds_per_vertex,
        g.evaluation.multiply_adds_per_vertex
    );
    assert_beats_baseline("Fox, local", Method::VertexLinear, &l.evaluation);
    let (lu, gu) = (
        l.evaluation.unseen_clips.as_ref().unwrap(),
        g.evaluation.unseen_clips.as_ref().unwrap(),
    );
    eprintln!(
        "Fox unseen clips: local {:+.2} dB, global {:+.2} dB",
        lu.mean_psnr_gain_db, gu.mean_psnr_gain_db
    );
    assert!(lu.mean_psnr_gain_db > gu.mean_psnr_gain_db);
}

#[test]
fn matrix_features_follow_the_milk_trucks_turning_wheels_on_unseen_clips() {
    // A wheel's AO is periodic in its angle; rotation vectors wrap at π
    // and a linear function of them cannot follow a whole turn, the
    // entries of the rotation matrix (cos, sin) can. Leave-one-clip-out,
    // every frame of the left-out clip.
    use aobake_core::method::vertex::Features;
    let imported = util::load(&util::character_path("CesiumMilkTruck.glb").unwrap());
    let unseen = |features: Features| {
        let mut p = quick(Method::VertexLinear);
        p.linear.features = features;
        let baked = bake(&imported.character, &imported.clips, p);
        baked.evaluation.unseen_clips.clone().unwrap()
    };
    let (matrix, vectors) = (unseen(Features::Matrix), unseen(Features::RotationVector));
    eprintln!(
        "truck unseen clips: matrix {:+.2} dB (worst {:+.2}), rotation vectors {:+.2} dB",
        matrix.mean_psnr_gain_db, matrix.min_psnr_gain_db, vectors.mean_psnr_gain_db
    );
    assert_eq!(matrix.folds.len(), 2);
    assert!(matrix.min_psnr_gain_db > 6.0, "{matrix:?}");
    assert!(matrix.mean_psnr_gain_db > vectors.mean_psnr_gain_db + 3.0);
}

#[test]
fn a_linear_base_carries_vertex_clustered_to_fox_clips_it_never_saw() {
    // Kirk & Arikan's clusters on the mean AO extrapolate poorly to a
    // left-out clip; on a vertex-linear base they model only what it
    // leaves. Leave-one-clip-out over Fox's three clips.
    use aobake_core::method::vertex::Base;
    let imported = util::load(&util::character_path("Fox.glb").unwrap());
    let unseen = |base: Base, basis: usize| {
        let mut p = quick(Method::VertexClustered);
        p.poses = 256;
        p.clustered.base = base;
        p.clustered.basis = basis;
        let baked = bake(&imported.character, &imported.clips, p);
        let Model::VertexClustered(_, m) = &baked.model else {
            panic!("a clustered model")
        };
        assert_eq!(m.base.is_some(), base == Base::Linear);
        assert_eq!(m.basis.is_some(), basis > 0);
        (
            baked.evaluation.unseen_clips.clone().unwrap(),
            baked.evaluation.multiply_adds_per_vertex,
        )
    };
    let (linear, mean) = (unseen(Base::Linear, 0), unseen(Base::Mean, 0));
    eprintln!(
        "Fox unseen clips, vertex-clustered: linear base {:+.2} dB (worst {:+.2}, {:.1} multiply-adds a vertex), mean {:+.2} dB (worst {:+.2}, {:.1})",
        linear.0.mean_psnr_gain_db,
        linear.0.min_psnr_gain_db,
        linear.1,
        mean.0.mean_psnr_gain_db,
        mean.0.min_psnr_gain_db,
        mean.1,
    );
    assert_eq!(linear.0.folds.len(), 3);
    assert!(linear.0.min_psnr_gain_db > 0.5, "{linear:?}");
    assert!(linear.0.mean_psnr_gain_db > mean.0.mean_psnr_gain_db + 1.0);
    // The eigen-AO basis: the same model in 32 rows keeps the gain at a
    // fraction of the per-vertex cost, within 2× the paper's.
    let basis = unseen(Base::Linear, 32);
    eprintln!(
        "with a 32-row basis: {:+.2} dB (worst {:+.2}), {:.1} multiply-adds a vertex",
        basis.0.mean_psnr_gain_db, basis.0.min_psnr_gain_db, basis.1
    );
    assert!(basis.0.min_psnr_gain_db > 0.5, "{basis:?}");
    assert!(basis.0.mean_psnr_gain_db > linear.0.mean_psnr_gain_db - 0.5);
    assert!(
        basis.1 <= 33.0 && linear.1 > 2.0 * mean.1,
        "{basis:?} {linear:?}"
    );
    assert!(basis.1 <= 2.0 * mean.1, "{basis:?} {mean:?}");
}

/// A vertex that draws nothing in a pose (InterpolationTest's "Step
/// Scale" clip scales a cube to zero half the time) has no AO to be
/// judged on: the errors leave it out, and the report counts it.
#[test]
fn vertices_that_draw_nothing_are_left_out_of_the_errors() {
    use aobake_core::asset::metrics::FrameError;
    let imported = util::load(&util::character_path("InterpolationTest.glb").unwrap());
    let c = &imported.character;
    let clip = imported
        .clips
        .iter()
        .find(|k| k.name == "Step Scale")
        .unwrap();
    let drawn = |t: f32| c.drawn_vertices(&c.skin(&Pose::sample(&c.skeleton, clip, t)).positions);
    // Keys at 0, 0.5, 1, … s: scale 1, then 0, stepwise.
    let (whole, gone) = (drawn(0.25), drawn(0.75));
    assert!(whole.iter().all(|&d| d), "every vertex draws at scale 1");
    let hidden = gone.iter().filter(|&&d| !d).count();
    assert_eq!(hidden, 24, "the cube's 24 vertices draw nothing at scale 0");
    // A prediction wrong only there has no error; without the mask it has.
    let truth = vec![0.25f32; c.vertex_count()];
    let predicted: Vec<f32> = gone
        .iter()
        .zip(&truth)
        .map(|(&d, &t)| if d { t } else { 1.0 })
        .collect();
    assert_eq!(
        FrameError::of_drawn(&predicted, &truth, Some(&gone)).rmse,
        0.0
    );
    assert!(FrameError::of(&predicted, &truth).rmse > 0.1);
    // The bake's evaluation counts the vertex-frames it left out: the
    // cube's vertices in each held-out frame of the three scale clips
    // where the cube is at zero.
    let mut params = quick(Method::VertexLinear);
    params.eval_folds = 0;
    let inputs = util::inputs(c, &imported.clips);
    let bake = Bake::new(&inputs, params).unwrap();
    let expected: usize = bake
        .plan
        .test_poses()
        .iter()
        .map(|t| {
            let posed = c.skin(&t.pose);
            c.drawn_vertices(&posed.positions)
                .iter()
                .filter(|&&d| !d)
                .count()
        })
        .sum();
    assert!(expected >= 24, "some held-out frames hide a cube");
    let baked = bake_in_process(&bake, None).unwrap();
    let e = &baked.report.vertex().unwrap().evaluation;
    assert_eq!(e.undrawn_vertex_frames, expected);
}
