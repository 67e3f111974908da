//! texel-linear end to end in this process: the vertex family's jobs over
//! the texels of a generated atlas, its asset (the model with its atlas),
//! read back and checked against characters, evaluated at vertices, and
//! its textures.

use aobake_core::{
    Pose,
    asset::Container,
    bake::{AssetUseError, Bake, BakeParams, BakedAsset, Receivers, bake_in_process},
    method::{Method, texel::TexelModel},
};

use crate::util;

#[test]
fn a_texel_bake_fits_per_texel_round_trips_and_beats_its_static_average() {
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let c = &imported.character;
    let mut p = BakeParams::new(Method::TexelLinear);
    p.poses = 96;
    p.samples = 32;
    p.eval_poses = 8;
    p.eval_fps = 15.0;
    p.texel.atlas = 64;
    let inputs = util::inputs(c, &imported.clips);
    let bake = Bake::new(&inputs, p.clone()).unwrap();
    let Receivers::Texels(atlas) = &bake.plan.receivers else {
        panic!("a texel bake traces texels");
    };
    let texels = atlas.texels.len();
    assert!(texels > c.vertex_count(), "{texels} texels");
    let a = bake_in_process(&bake, None).unwrap();
    let again = bake_in_process(&Bake::new(&inputs, p.clone()).unwrap(), None).unwrap();
    assert_eq!(a.asset, again.asset, "same request, same bytes");

    // The asset: the model over the texels, with the plan's atlas.
    let container = Container::from_bytes(&a.asset).unwrap();
    assert_eq!(container.method, Method::TexelLinear);
    let (model, header) = TexelModel::from_container(&container, Some(c.vertex_count())).unwrap();
    assert_eq!(header.vertices, texels);
    assert_eq!(model.atlas, atlas.layout());
    assert!(header.primitives.is_empty());

    // Judged per texel on held-out clip frames, ahead of the texel static
    // average.
    let report = a.report.vertex().expect("the vertex family's report");
    let frames = &report.evaluation.training_clip_frames;
    assert!(
        frames.psnr_gain_db > 0.5,
        "texel-linear {:+.2} dB over its static average",
        frames.psnr_gain_db
    );
    assert_eq!(report.sizes.baseline_bytes, 2 * texels);
    // The report's atlas and what its textures cost per pixel.
    let atlas_report = report
        .texel
        .as_ref()
        .expect("a texel bake reports its atlas");
    assert_eq!((atlas_report.width, atlas_report.texels), (64, texels));
    assert_eq!(atlas_report.utilisation, atlas.texels.utilisation());
    assert!(atlas_report.utilisation > 0.0 && atlas_report.utilisation <= 1.0);

    // Read as a published asset with its character.
    let baked = BakedAsset::read(&container, Some(c)).unwrap();
    let pose = Pose::sample(&c.skeleton, &imported.clips[0], 0.4);
    let ao = baked.vertex_ao(c, &pose, &c.skin(&pose)).unwrap();
    assert_eq!(ao.len(), c.vertex_count());
    assert!(ao.iter().all(|v| (0.0..=1.0).contains(v)));
    assert!(ao.iter().any(|&v| v > 0.05), "some vertices are occluded");
    // Its previews draw the model per pixel over the asset's atlas, whose
    // texels are the plan's (found again from the asset's UVs).
    match baked.preview_model().unwrap().0 {
        aobake_core::bake::PreviewModel::Texel(m, a) => {
            assert_eq!(m.atlas, atlas.layout());
            assert_eq!(a.texels, atlas.texels);
        }
        _ => panic!("a texel asset previews as a texel model"),
    }

    // Its textures give back the model: at each texel, the pose's weights
    // times the textures' values are the model's value there.
    let images = baked.images(&[]).unwrap();
    let w = model.model.weights(&c.skeleton, &pose.locals);
    assert_eq!(atlas_report.textures, w.len());
    assert_eq!(
        atlas_report.texture_bytes,
        2 * u64::from(model.atlas.width * model.atlas.height) * w.len() as u64
    );
    assert_eq!(images.len(), 1);
    assert_eq!(images[0].channels.len(), w.len());
    assert_eq!(
        (images[0].width, images[0].height),
        (model.atlas.width as usize, model.atlas.height as usize)
    );
    let values = model.model.evaluate_weights(&w);
    for (column, &t) in model.atlas.texels.iter().enumerate() {
        let sum: f32 = images[0]
            .channels
            .iter()
            .zip(&w)
            .map(|((_, image), wk)| wk * image[t as usize])
            .sum();
        assert!(
            (sum.clamp(0.0, 1.0) - values[column]).abs() < 1e-5,
            "texel {t}: {sum} against {}",
            values[column]
        );
    }

    // Another character's asset is refused by name.
    let other = util::load(&util::character_path("CesiumMan.glb").unwrap());
    let refused = BakedAsset::read(&container, Some(&other.character)).unwrap_err();
    assert!(
        matches!(
            refused,
            AssetUseError::Mismatch(_) | AssetUseError::Unreadable(_)
        ),
        "{refused}"
    );
}

#[test]
fn texel_options_are_checked_and_keyed() {
    let mut p = BakeParams::new(Method::TexelLinear);
    assert_eq!(p.texel.atlas, aobake_core::method::texel::DEFAULT_ATLAS);
    p.texel.atlas = 8;
    assert!(
        p.validate()
            .unwrap_err()
            .to_string()
            .contains("texel.atlas")
    );
    // Its own blocks are the linear fit's and the atlas's; another
    // method's is refused, and the atlas is no vertex method's option.
    let own = serde_json::json!({"texel.atlas": 128, "linear.ridge": 0.1});
    let p = BakeParams::with_overrides(Method::TexelLinear, own.as_object().unwrap()).unwrap();
    assert_eq!((p.texel.atlas, p.linear.ridge), (128, 0.1));
    let canonical = p.canonical();
    assert!(canonical.get("texel").is_some() && canonical.get("grid").is_none());
    let foreign = serde_json::json!({"texel.atlas": 128});
    let e = BakeParams::with_overrides(Method::VertexLinear, foreign.as_object().unwrap())
        .unwrap_err()
        .to_string();
    assert!(e.contains("texel-linear"), "{e}");
    // A texel's joints are not gathered: no local fit.
    let local = serde_json::json!({"linear.locality": "on"});
    assert!(BakeParams::with_overrides(Method::TexelLinear, local.as_object().unwrap()).is_err());
    // Each weight is a layer of a GPU array texture: the basis is kept
    // under their number, and a model without one (basis 0) is refused.
    for basis in [0, aobake_core::method::texel::MAX_TEXTURES] {
        let wide = serde_json::json!({"linear.basis": basis});
        let e = BakeParams::with_overrides(Method::TexelLinear, wide.as_object().unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("linear.basis") && e.contains("layer"), "{e}");
    }
    let most = serde_json::json!({"linear.basis": aobake_core::method::texel::MAX_TEXTURES - 1});
    assert!(BakeParams::with_overrides(Method::TexelLinear, most.as_object().unwrap()).is_ok());
}

#[test]
fn a_uv_set_of_the_characters_own_is_the_atlas_or_is_refused_by_name() {
    let plan_with = |name: &str, set: u32| {
        let imported = util::load(&util::character_path(name).unwrap());
        let mut p = BakeParams::new(Method::TexelLinear);
        p.texel.uv_set = Some(set);
        let receivers = aobake_core::bake::Plan::new(&imported.character, &imported.clips, p)
            .map(|plan| plan.receivers);
        (imported.character, receivers)
    };
    // CesiumMan's TEXCOORD_0: 138 islands, no two places on one texel.
    let (c, receivers) = plan_with("CesiumMan.glb", 0);
    let Ok(Receivers::Texels(atlas)) = receivers else {
        panic!("{:?}", receivers.err());
    };
    let own = c.uv_sets[0].as_ref().unwrap();
    assert_eq!(own.len(), c.vertex_count());
    assert_eq!(&atlas.atlas.uvs, own);
    assert_eq!(atlas.atlas.charts, 138);
    // The milk truck's second primitive has no TEXCOORD_0; the figure has
    // no UV set at all.
    let (_, refused) = plan_with("CesiumMilkTruck.glb", 0);
    let e = refused.err().unwrap().to_string();
    assert!(
        e.contains("meshes[0].primitives[1] has no TEXCOORD_0"),
        "{e}"
    );
    let (_, refused) = plan_with("RiggedFigure.glb", 0);
    let e = refused.err().unwrap().to_string();
    assert!(e.contains("no TEXCOORD_0"), "{e}");
}
