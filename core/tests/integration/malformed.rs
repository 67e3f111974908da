//! Hostile and broken input: each case gives a clear, typed error that
//! names what is wrong; none panics; none reads a file outside the upload.

use aobake_core::{ImportError, Limits, SideFile, Upload, import_character};
use aobake_e2e::hostile::Verdict;
use serde_json::json;

use crate::util::{self, Gltf};

/// The tiny rig's accessor of key times.
const KEY_TIMES: usize = 5;

fn import_with(main: &[u8], side_files: &[SideFile]) -> Result<aobake_core::Imported, ImportError> {
    import_character(Upload { main, side_files }, &Limits::default())
}

fn import(bytes: &[u8]) -> Result<aobake_core::Imported, ImportError> {
    import_character(Upload::single(bytes), &Limits::default())
}

fn expect_err(g: &Gltf, needle: &str) -> ImportError {
    let err = g
        .import()
        .err()
        .unwrap_or_else(|| panic!("expected an error containing {needle:?}"));
    assert!(
        err.to_string().contains(needle),
        "error {err:?} does not contain {needle:?}"
    );
    err
}

#[test]
fn the_tiny_rig_itself_is_valid() {
    let imported = util::tiny_rig().import().unwrap();
    assert_eq!(imported.character.vertex_count(), 8);
    assert_eq!(imported.clips.len(), 1);
}

#[test]
fn truncated_glb_at_every_length_is_an_error() {
    let path = util::character_path("RiggedSimple.glb").unwrap();
    let bytes = std::fs::read(path).unwrap();
    for len in (0..bytes.len()).step_by(7) {
        let err = import(&bytes[..len]).err();
        assert!(err.is_some(), "truncated to {len} bytes, yet it imported");
    }
}

#[test]
fn lying_chunk_lengths() {
    let glb = util::tiny_rig().glb();
    // Total length larger than the file.
    let mut lie = glb.clone();
    lie[8..12].copy_from_slice(&(glb.len() as u32 + 100).to_le_bytes());
    assert!(matches!(import(&lie), Err(ImportError::Container(m)) if m.contains("declares")));
    // Total length below the header.
    lie[8..12].copy_from_slice(&3u32.to_le_bytes());
    assert!(matches!(import(&lie), Err(ImportError::Container(_))));
    // JSON chunk longer than the rest.
    let mut lie = glb.clone();
    lie[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(matches!(import(&lie), Err(ImportError::Container(m)) if m.contains("chunk 0")));
    // BIN chunk longer than the rest.
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let mut lie = glb.clone();
    lie[20 + json_len..24 + json_len].copy_from_slice(&1_000_000u32.to_le_bytes());
    assert!(matches!(import(&lie), Err(ImportError::Container(m)) if m.contains("chunk 1")));
    // BIN chunk shorter than the buffer's byteLength.
    let mut lie = glb[..20 + json_len + 8 + 8].to_vec();
    lie[20 + json_len..24 + json_len].copy_from_slice(&8u32.to_le_bytes());
    let total = lie.len() as u32;
    lie[8..12].copy_from_slice(&total.to_le_bytes());
    let err = import(&lie).unwrap_err();
    assert!(err.to_string().contains("buffers[0]"), "{err}");
}

#[test]
fn accessor_count_past_the_buffer() {
    let mut g = util::tiny_rig();
    g.json["accessors"][0]["count"] = json!(9);
    let err = expect_err(&g, "accessors[0]");
    assert!(err.to_string().contains("do not fit"), "{err}");
    let mut g = util::tiny_rig();
    g.json["accessors"][0]["byteOffset"] = json!(4);
    expect_err(&g, "do not fit");
    let mut g = util::tiny_rig();
    g.json["bufferViews"][0]["byteLength"] = json!(1 << 30);
    expect_err(&g, "bufferViews[0]");
}

#[test]
fn index_past_the_vertices() {
    let mut g = util::tiny_rig();
    // Patch the first index (u16 at the index view's offset) to 8.
    let offset = g.accessor_offset(1);
    g.bin[offset..offset + 2].copy_from_slice(&8u16.to_le_bytes());
    let err = expect_err(&g, "meshes[0].primitives[0].indices");
    assert!(
        err.to_string()
            .contains("index 0 (accessor 1) is 8, but POSITION has 8 vertices"),
        "{err}"
    );
}

#[test]
fn joint_index_past_the_skin() {
    let mut g = util::tiny_rig();
    let offset = g.accessor_offset(2);
    g.bin[offset + 8 * 5..offset + 8 * 5 + 2].copy_from_slice(&7u16.to_le_bytes());
    let err = expect_err(&g, "JOINTS_0");
    assert!(err.to_string().contains("vertex 5 uses joint 7"), "{err}");
    assert!(err.to_string().contains("skin 0 has 2 joints"), "{err}");
}

#[test]
fn path_traversal_and_absolute_uris_never_touch_the_file_system() {
    let g = util::tiny_rig();
    // A file that must not be read: its content would make a valid import.
    let outside = std::env::temp_dir().join(format!("aobake-secret-{}.bin", std::process::id()));
    std::fs::write(&outside, &g.bin).unwrap();
    let abs = outside.display().to_string();
    for uri in [
        "../secret.bin".to_owned(),
        "sub/../../secret.bin".to_owned(),
        "%2E%2E/secret.bin".to_owned(),
        abs.clone(),
        format!("file://{abs}"),
        "http://127.0.0.1:1/secret.bin".to_owned(),
        "\\\\server\\share\\secret.bin".to_owned(),
    ] {
        let (main, side) = g.with_side_file(&uri, "secret.bin");
        let err = import_with(&main, &side).unwrap_err();
        assert!(
            matches!(err, ImportError::ForbiddenUri { .. }),
            "{uri}: {err}"
        );
        assert!(err.to_string().contains("buffers[0].uri"), "{err}");
    }
    std::fs::remove_file(outside).unwrap();
}

#[test]
fn side_files_resolve_by_name_only() {
    let g = util::tiny_rig();
    let (main, side) = g.with_side_file("data/rig%20mesh.bin", "data/rig mesh.bin");
    assert!(import_with(&main, &side).is_ok());
    // A unique base name matches too.
    let (main, side) = g.with_side_file("deep/dir/rig.bin", "rig.bin");
    assert!(import_with(&main, &side).is_ok());
    // A missing one names what was uploaded.
    let (main, _) = g.with_side_file("rig.bin", "rig.bin");
    let other = [SideFile {
        name: "other.bin".into(),
        bytes: vec![],
    }];
    let err = import_with(&main, &other).unwrap_err();
    assert_eq!(
        err.to_string(),
        "buffers[0].uri: file \"rig.bin\" is not among the files given with the glTF (given: other.bin)"
    );
}

#[test]
fn nan_and_infinite_data() {
    // NaN keyframe time.
    let mut g = util::tiny_rig();
    let offset = g.accessor_offset(KEY_TIMES);
    g.bin[offset + 4..offset + 8].copy_from_slice(&f32::NAN.to_le_bytes());
    let err = expect_err(&g, "accessors[5]");
    assert!(
        err.to_string().contains("element 1 component 0 is NaN"),
        "{err}"
    );
    // Infinite position.
    let mut g = util::tiny_rig();
    g.bin[12..16].copy_from_slice(&f32::INFINITY.to_le_bytes());
    expect_err(&g, "element 1 component 0 is inf");
    // Out-of-range node translation (parses as infinity).
    let mut g = util::tiny_rig();
    g.json["nodes"][1]["translation"] = json!([1e39, 0.0, 0.0]);
    expect_err(&g, "nodes[1]");
}

#[test]
fn cyclic_and_shared_node_graphs() {
    let mut g = util::tiny_rig();
    g.json["nodes"][1]["children"] = json!([0]);
    expect_err(&g, "cycle");
    // Each refusal points at the child entry that is wrong.
    let mut g = util::tiny_rig();
    g.json["nodes"][2]["children"] = json!([1]);
    let err = expect_err(&g, "already a child");
    assert_eq!(err.pointer().as_deref(), Some("/nodes/2/children/0"));
    let mut g = util::tiny_rig();
    g.json["nodes"][1]["children"] = json!([1]);
    let err = expect_err(&g, "own child");
    assert_eq!(err.pointer().as_deref(), Some("/nodes/1/children/0"));
    let mut g = util::tiny_rig();
    let children = g.json["nodes"][0]["children"][0].clone();
    g.json["nodes"][0]["children"] = json!([children, children]);
    let err = expect_err(&g, "repeats 1 (first at [0])");
    assert_eq!(err.pointer().as_deref(), Some("/nodes/0/children/1"));
}

#[test]
fn huge_declared_counts_are_refused_before_allocation() {
    let mut g = util::tiny_rig();
    g.json["accessors"][0]["count"] = json!(4_000_000_000u64);
    let err = expect_err(&g, "vertex count is");
    assert_eq!(err.code(), "limit_exceeded");
    let mut g = util::tiny_rig();
    g.json["accessors"][5]["count"] = json!(u32::MAX);
    expect_err(&g, "keyframe count is");
    let limits = Limits {
        max_joints: 1,
        ..Limits::default()
    };
    let err = import_character(Upload::single(&util::tiny_rig().glb()), &limits).unwrap_err();
    assert_eq!(err.to_string(), "joint count is 2, over the limit of 1");
    let limits = Limits {
        max_file_bytes: 100,
        ..Limits::default()
    };
    assert!(import_character(Upload::single(&util::tiny_rig().glb()), &limits).is_err());
}

/// Buffers that all name one side file declare their bytes against the
/// upload's limit together: each is a copy, so 64 buffers of a 250 MiB
/// file would hold 16 GiB.
#[test]
fn buffers_sharing_a_side_file_are_held_to_the_upload_limit() {
    let g = util::tiny_rig();
    let (main, side) = g.with_side_file("rig.bin", "rig.bin");
    let mut json: serde_json::Value = serde_json::from_slice(&main).unwrap();
    let buffer = json["buffers"][0].clone();
    let len = buffer["byteLength"].as_u64().unwrap();
    json["buffers"] = json!(vec![buffer; 64]);
    let main = serde_json::to_vec(&json).unwrap();
    let limits = Limits {
        max_file_bytes: main.len() as u64 + len * 2,
        ..Limits::default()
    };
    let upload = Upload {
        main: &main,
        side_files: &side,
    };
    let err = import_character(upload, &limits).unwrap_err();
    assert_eq!(err.code(), "limit_exceeded");
    assert!(
        err.to_string()
            .starts_with(&format!("bytes the buffers declare in all is {}", 64 * len)),
        "{err}"
    );
    // Under the limit they import, each holding its declared bytes.
    assert!(import_character(upload, &Limits::default()).is_ok());
}

/// Accessors without a bufferView are zeros the file need not carry: a
/// few bytes of JSON could declare gigabytes of them, so what they decode
/// to has a limit of its own, over the whole file.
#[test]
fn zeros_without_data_are_held_to_a_budget() {
    let mut g = util::tiny_rig();
    g.json["accessors"][0]
        .as_object_mut()
        .unwrap()
        .remove("bufferView");
    let limits = Limits {
        max_zero_filled: 10,
        ..Limits::default()
    };
    let err = import_character(Upload::single(&g.glb()), &limits).unwrap_err();
    assert_eq!(err.code(), "limit_exceeded");
    assert_eq!(
        err.to_string(),
        "accessors[0]: numbers decoded from accessors without a bufferView (zeros the file does not carry) is 24, over the limit of 10"
    );
}

/// JSON of many small values (each a parsed node of tens of bytes) is
/// refused before it is parsed.
#[test]
fn json_of_too_many_values_is_refused() {
    let mut g = util::tiny_rig();
    g.json["extras"] = json!(vec![0; 10_000]);
    let limits = Limits {
        max_json_values: 5_000,
        ..Limits::default()
    };
    let err = import_character(Upload::single(&g.glb()), &limits).unwrap_err();
    assert_eq!(err.code(), "limit_exceeded");
    assert!(
        err.to_string()
            .starts_with("values in the JSON (numbers, strings, arrays, objects) is 5001"),
        "{err}"
    );
    assert!(g.import().is_ok());
}

/// Clip names are keys (of reports, of `--held-out`): a renamed
/// duplicate never takes a name another clip has.
#[test]
fn clip_names_stay_unique() {
    let mut g = util::tiny_rig();
    let animation = g.json["animations"][0].clone();
    let named = |name: &str| {
        let mut a = animation.clone();
        a["name"] = json!(name);
        a
    };
    g.json["animations"] = json!([named("walk"), named("walk_2"), named("walk")]);
    let imported = g.import().unwrap();
    let names: Vec<&str> = imported.clips.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["walk", "walk_2", "walk_2_2"]);
    assert!(
        imported
            .warnings
            .iter()
            .any(|w| w.contains(r#"name "walk" is used twice; this one is "walk_2_2""#)),
        "{:?}",
        imported.warnings
    );
    // And their number is bounded (each is skinned for the summary).
    let limits = Limits {
        max_animations: 2,
        ..Limits::default()
    };
    let err = import_character(Upload::single(&g.glb()), &limits).unwrap_err();
    assert_eq!(err.to_string(), "animation count is 3, over the limit of 2");
}

#[test]
fn deep_json_nesting_is_refused() {
    let mut json = String::from(r#"{"asset":{"version":"2.0"},"extras":"#);
    json.push_str(&"[".repeat(10_000));
    json.push_str(&"]".repeat(10_000));
    json.push('}');
    let err = import(json.as_bytes()).unwrap_err();
    assert_eq!(err.code(), "limit_exceeded");
    assert!(
        err.to_string().starts_with("JSON nesting depth is 65"),
        "{err}"
    );
}

#[test]
fn not_gltf_at_all() {
    for bytes in [
        &b""[..],
        b"hello",
        b"{}",
        b"[1,2,3]",
        b"{\"asset\":{\"version\":\"2.0\"}}",
        b"glTF",
    ] {
        let err = import(bytes).unwrap_err();
        assert!(!err.to_string().is_empty());
    }
    assert_eq!(
        import(b"{\"asset\":{\"version\":\"2.0\"}}").unwrap_err(),
        ImportError::NoGeometry
    );
}

#[test]
fn bad_references_and_types() {
    let mut g = util::tiny_rig();
    g.json["meshes"][0]["primitives"][0]["indices"] = json!(99);
    expect_err(&g, "index out of bounds");
    let mut g = util::tiny_rig();
    g.json["accessors"][0]["type"] = json!("VEC2");
    expect_err(&g, "must be a float VEC3");
    let mut g = util::tiny_rig();
    g.json["accessors"][0]["componentType"] = json!(1234);
    expect_err(&g, "accessors[0]");
    let mut g = util::tiny_rig();
    g.json["meshes"][0]["primitives"][0]["mode"] = json!(9);
    expect_err(&g, "mode");
    let mut g = util::tiny_rig();
    g.json["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    assert_eq!(
        g.import().unwrap_err(),
        ImportError::UnsupportedExtension {
            index: 0,
            name: "KHR_draco_mesh_compression".into()
        }
    );
    g.json["extensionsRequired"] = json!(["KHR_mesh_quantization", "KHR_draco_mesh_compression"]);
    let err = g.import().unwrap_err();
    assert_eq!(err.pointer().as_deref(), Some("/extensionsRequired/1"));
    assert!(err.to_string().contains("extensionsRequired[1]"), "{err}");
    let mut g = util::tiny_rig();
    g.json["animations"][0]["samplers"][0]["output"] = json!(4);
    expect_err(&g, "animations[0].samplers[0].output");
}

#[test]
fn absurd_key_times_and_empty_skins() {
    let mut g = util::tiny_rig();
    let offset = g.accessor_offset(KEY_TIMES);
    g.bin[offset + 4..offset + 8].copy_from_slice(&1e30f32.to_le_bytes());
    expect_err(
        &g,
        "key 1 is at 1000000000000000000000000000000 s, outside 0..=3600 s",
    );
    let mut g = util::tiny_rig();
    g.json["skins"][0]["joints"] = json!([]);
    expect_err(&g, "skins[0].joints: a skin needs at least one joint");
    let mut g = util::tiny_rig();
    g.json["accessors"][6]["count"] = json!(3);
    expect_err(&g, "has 3 elements; 2 keys of Rotation with Linear need 2");
}

#[test]
fn animation_target_node_out_of_range() {
    let mut g = util::tiny_rig();
    g.json["animations"][0]["channels"][0]["target"]["node"] = json!(9);
    expect_err(
        &g,
        "animations[0].channels[0].target.node: node 9 does not exist",
    );
}

#[test]
fn decreasing_key_times() {
    let mut g = util::tiny_rig();
    let offset = g.accessor_offset(KEY_TIMES);
    g.bin[offset..offset + 4].copy_from_slice(&2.0f32.to_le_bytes());
    expect_err(&g, "key times must strictly increase");
}

#[test]
fn fuzz_regressions_do_not_panic() {
    // Inputs that crashed the fuzzer once (`fuzz/regressions`): each must
    // now be refused with an error.
    let dir = util::repo().join("fuzz/regressions");
    let mut count = 0;
    for entry in std::fs::read_dir(&dir).unwrap().flatten() {
        let bytes = std::fs::read(entry.path()).unwrap();
        assert!(import(&bytes).is_err(), "{}", entry.path().display());
        count += 1;
    }
    assert!(count > 0);
}

#[test]
fn position_accessor_index_out_of_range() {
    let mut g = util::tiny_rig();
    g.json["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(77);
    expect_err(
        &g,
        "meshes[0].primitives[0].attributes[\"POSITION\"]: accessor 77 does not exist",
    );
}

/// What the Khronos validator reports as an error is refused
/// (docs/import-policy.md): a major version other than 2, a required
/// extension aobake does not know, key times that repeat, joint indices
/// outside the skin (`joint_index_past_the_skin`).
#[test]
fn validator_errors_are_refused() {
    for version in ["1.0", "3.0", "two", ""] {
        let mut g = util::tiny_rig();
        g.json["asset"]["version"] = json!(version);
        expect_err(&g, "asset.version");
    }
    let mut g = util::tiny_rig();
    g.json["asset"]["version"] = json!("2.1");
    g.import().unwrap();
    g.json["asset"]["minVersion"] = json!("2.1");
    expect_err(&g, "asset.minVersion");

    let mut g = util::tiny_rig();
    g.json["extensionsUsed"] = json!(["ACME_teleport"]);
    g.json["extensionsRequired"] = json!(["ACME_teleport"]);
    assert!(matches!(
        g.import(),
        Err(ImportError::UnsupportedExtension { name, .. }) if name == "ACME_teleport"
    ));
    // Appearance-only extensions are accepted with a warning.
    g.json["extensionsUsed"] = json!(["KHR_materials_unlit"]);
    g.json["extensionsRequired"] = json!(["KHR_materials_unlit"]);
    let imported = g.import().unwrap();
    assert!(
        imported
            .warnings
            .iter()
            .any(|w| w.contains("KHR_materials_unlit")),
        "{:?}",
        imported.warnings
    );

    let mut g = util::tiny_rig();
    let offset = g.accessor_offset(KEY_TIMES);
    let first = f32::from_le_bytes(g.bin[offset..offset + 4].try_into().unwrap());
    g.bin[offset + 4..offset + 8].copy_from_slice(&first.to_le_bytes());
    expect_err(&g, "key times must strictly increase");
}

/// The hostile corpus the service's tests upload (`aobake_e2e::hostile`)
/// is refused here too, each file with an error and none with a panic.
#[test]
fn the_shared_hostile_corpus_is_refused() {
    let valid = std::fs::read(util::character_path("RiggedSimple.glb").unwrap()).unwrap();
    import(&valid).unwrap();
    let corpus = aobake_e2e::hostile::corpus(&valid);
    assert!(corpus.len() > 30);
    for case in corpus {
        let err = import(&case.bytes).err();
        assert!(err.is_some(), "{} was accepted", case.name);
    }
}

/// Every file the Khronos validator reports errors in that aobake once
/// accepted is refused with an error naming its JSON path, or accepted
/// with the warning docs/import-policy.md promises.
#[test]
fn validator_errors_are_refused_or_warned_as_the_policy_says() {
    let valid = std::fs::read(util::character_path("RiggedSimple.glb").unwrap()).unwrap();
    let cases = aobake_e2e::hostile::validator_errors(&valid);
    assert!(cases.len() >= 20);
    for (case, verdict) in cases {
        match (import(&case.bytes), verdict) {
            (Err(e), Verdict::Refused { path }) => {
                let message = e.to_string();
                assert!(
                    message.contains(path),
                    "{}: {message:?} does not name {path:?}",
                    case.name
                );
            }
            (Ok(imported), Verdict::Warned { about }) => assert!(
                imported.warnings.iter().any(|w| w.contains(about)),
                "{}: no warning about {about:?} in {:?}",
                case.name,
                imported.warnings
            ),
            (result, verdict) => panic!(
                "{}: expected {verdict:?}, got {:?}",
                case.name,
                result.map(|i| i.warnings)
            ),
        }
    }
}

/// The corpus above is broken in the Khronos validator's eyes too: each
/// case has errors, among them the code its name gives. Runs where node
/// and the validator are installed (`npm ci --prefix tests/tools`; `.ci/run`
/// does it and sets AOBAKE_REQUIRE_VALIDATOR, which makes a missing
/// validator a failure).
#[test]
fn the_khronos_validator_reports_an_error_in_every_case() {
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/tools/gltf-validate.mjs");
    let required = std::env::var_os("AOBAKE_REQUIRE_VALIDATOR").is_some();
    let valid = std::fs::read(util::character_path("RiggedSimple.glb").unwrap()).unwrap();
    let cases = aobake_e2e::hostile::validator_errors(&valid);
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("validator-corpus");
    std::fs::create_dir_all(&dir).unwrap();
    let files: Vec<_> = cases
        .iter()
        .enumerate()
        .map(|(i, (case, _))| {
            let file = dir.join(format!("{i:02}.glb"));
            std::fs::write(&file, &case.bytes).unwrap();
            file
        })
        .collect();
    let out = match std::process::Command::new("node")
        .arg(&script)
        .args(&files)
        .output()
    {
        Ok(out) if out.status.success() => out,
        other => {
            let why = format!("the Khronos validator did not run: {other:?}");
            assert!(!required, "{why}");
            eprintln!("skipped: {why}");
            return;
        }
    };
    let lines: Vec<serde_json::Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), cases.len());
    for ((case, _), report) in cases.iter().zip(&lines) {
        let code = case.name.rsplit_once('(').unwrap().1.trim_end_matches(')');
        let codes: Vec<&str> = report["codes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_str().unwrap())
            .collect();
        assert!(
            codes.contains(&code),
            "{}: the validator reports {codes:?}",
            case.name
        );
    }
}

/// Only indices and enums are 32-bit in glTF: a wide integer there is
/// refused (gltf-json would wrap it), anywhere else it is a number like
/// any other (JSON writers print 5e9 as 5000000000).
#[test]
fn wide_integers_are_refused_only_where_gltf_has_32_bits() {
    let mut g = util::tiny_rig();
    g.json["nodes"][0]["translation"] = json!([5_000_000_000u64, 0, 0]);
    g.json["extras"] = json!({"id": 1u64 << 40});
    g.import().unwrap();
    let mut g = util::tiny_rig();
    let position = g.json["meshes"][0]["primitives"][0]["attributes"]["POSITION"].clone();
    g.json["meshes"][0]["primitives"][0]["attributes"]["POSITION"] =
        json!(position.as_u64().unwrap() + (1u64 << 32));
    expect_err(&g, "meshes[0].primitives[0].attributes.POSITION");
    let mut g = util::tiny_rig();
    g.json["scenes"] = json!([{ "nodes": [1u64 << 32] }]);
    expect_err(&g, "scenes[0].nodes[0]");
}
