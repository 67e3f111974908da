//! A texel-linear bake through the service (issue 50): the vertex
//! family's sample, fit, unseen and evaluate jobs over the texels of the
//! atlas the plan generates, on a worker process; the asset equals
//! `aobake bake`'s byte for byte, and `aobake export --exr` writes its
//! coefficient textures, read back here with the exr crate's reader.

use std::time::Duration;

use aobake_core::{
    asset::Container,
    method::{texel::TexelModel, vertex::FormRef},
};
use aobake_e2e::{ADMIN, Options, TestEnv, character};
use serde_json::json;

use crate::util::{aobake_bake, asset, export_exr, exr_channel, upload};

#[test]
fn a_texel_bake_through_the_service_matches_aobake_bake_and_exports_its_textures() {
    let mut env = TestEnv::start(Options::default());
    env.start_worker(&[]);
    let figure = character("RiggedFigure");
    let digest = upload(&env, &figure);
    let params = json!({"poses": 48, "samples": 16, "eval_poses": 4, "eval_fps": 5.0,
        "eval_folds": 2, "texel": {"atlas": 64}});
    let (status, b) = env
        .request(
            "POST",
            "/v1/bakes",
            ADMIN,
            Some(json!({"character": digest, "method": "texel-linear", "params": params})),
        )
        .unwrap();
    assert_eq!(status, 202, "{b}");
    // A UV set the figure does not have is refused at once, by name.
    let (refused, problem) = env
        .request(
            "POST",
            "/v1/bakes",
            ADMIN,
            Some(json!({"character": digest, "method": "texel-linear",
                "params": {"texel": {"uv_set": 0}}})),
        )
        .unwrap();
    assert!((400..500).contains(&refused), "{refused} {problem}");
    assert!(
        problem["detail"]
            .as_str()
            .is_some_and(|d| d.contains("no TEXCOORD_0")),
        "{problem}"
    );
    let id = b["id"].as_i64().unwrap();
    let done = env.wait_bake(id, Duration::from_secs(300));
    assert_eq!(done["state"], "done", "{done}");
    // Its previews, drawn per pixel from the textures by the worker, each
    // still judging the model beside GTAO and the texel floor.
    let (status, previews) = env
        .request("GET", &format!("/v1/bakes/{id}/previews"), ADMIN, None)
        .unwrap();
    assert_eq!(status, 200);
    assert_eq!(previews["state"], "completed", "{previews}");
    let stills: Vec<&serde_json::Value> = previews["previews"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["kind"] == "still")
        .collect();
    assert!(!stills.is_empty(), "{previews}");
    for still in stills {
        let on_character = &still["screen_space"]["character"];
        assert!(on_character["model"]["rmse"].is_number(), "{still}");
        assert!(on_character["texel_truth"]["rmse"].is_number(), "{still}");
        assert_eq!(still["screen_space"]["atlas"]["width"], 64, "{still}");
    }
    // Pooled per pixel: one clip, no folds (the figure has one clip).
    let pixels = &previews["pixels"];
    assert_eq!(
        pixels["stills"].as_array().map(Vec::len),
        Some(1),
        "{pixels}"
    );
    assert!(pixels["stills"][0]["texel_floor"].is_number(), "{pixels}");
    assert_eq!(pixels["unseen"], json!([]), "{pixels}");
    let served = asset(&env, &done);
    let flags = [
        "--method",
        "texel-linear",
        "--poses",
        "48",
        "--samples",
        "16",
        "--eval-poses",
        "4",
        "--eval-fps",
        "5",
        "--param",
        "eval_folds=2",
        "--param",
        "texel.atlas=64",
    ];
    let local = aobake_bake(env.dir.path(), &figure, &flags, "local");
    assert!(
        served == local,
        "the service's asset differs from aobake bake's"
    );

    // `aobake export --exr`: one file, a channel per coefficient row,
    // each the row scattered into the atlas and dilated, bit for bit.
    let exr_dir = export_exr(&env, &served);
    let (model, _) =
        TexelModel::from_container(&Container::from_bytes(&served).unwrap(), None).unwrap();
    let FormRef::Dense(form) = model.model.form() else {
        panic!("a texel model's rows are dense");
    };
    let image = exr::prelude::read_all_flat_layers_from_file(exr_dir.join("texel-ao.exr")).unwrap();
    let layer = &image.layer_data[0];
    assert_eq!(
        (layer.size.width(), layer.size.height()),
        (model.atlas.width as usize, model.atlas.height as usize)
    );
    assert_eq!(layer.channel_data.list.len(), model.model.weight_count());
    let block = &form.blocks[0];
    for k in [0, block.rows - 1] {
        let row: Vec<f32> = block.coefficients[k * block.columns..(k + 1) * block.columns]
            .iter()
            .map(|c| c.to_f32())
            .collect();
        let name = format!("w{k:02}");
        assert_eq!(
            exr_channel(layer, &name),
            model.atlas.image(&row),
            "{name} bit for bit"
        );
    }
}
