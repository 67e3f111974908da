//! glTF features on small synthetic files: every accessor type, sparse
//! accessors, strips and fans, non-indexed meshes, computed normals,
//! morph targets, several skins, rigid nodes, several influence sets, and
//! clips from a second file.

use aobake_core::{Limits, Pose, Upload, import_clips};
use glam::Vec3;
use serde_json::json;

use crate::util::{self, Gltf, U8, U16};

fn close(a: Vec3, b: Vec3) -> bool {
    a.distance(b) < 1e-5
}

#[test]
fn tiny_rig_bends_as_expected() {
    let imported = util::tiny_rig().import().unwrap();
    let c = &imported.character;
    let bind = c.skin(&Pose::bind(c));
    for (p, q) in bind.positions.iter().zip(&c.positions) {
        assert!(close(*p, *q), "bind pose must return the modelled mesh");
    }
    let pose = Pose::sample(&c.skeleton, &imported.clips[0], 1.0);
    let posed = c.skin(&pose);
    // Vertex 7 at (0.5, 3, 0), bound to joint 1 at y=1.5, rotated 90° about z:
    // relative (0.5, 1.5) -> (-1.5, 0.5), plus the joint.
    assert!(
        close(posed.positions[7], Vec3::new(-1.5, 2.0, 0.0)),
        "{}",
        posed.positions[7]
    );
    assert!(close(posed.positions[0], Vec3::new(-0.5, 0.0, 0.0)));
    // Computed normals follow the bent upper quad: +z stays +z.
    assert!(close(posed.normals[7], Vec3::Z), "{}", posed.normals[7]);
}

#[test]
fn embedded_gltf_and_glb_give_the_same_character() {
    let g = util::tiny_rig();
    let a = g.import().unwrap();
    let embedded = g.embedded();
    let b = aobake_core::import_character(Upload::single(&embedded), &Limits::default()).unwrap();
    assert_eq!(a.character.positions, b.character.positions);
    assert_eq!(a.character.triangles, b.character.triangles);
}

/// A rigid (unskinned) mesh built from one primitive.
fn rigid(g: &mut Gltf, primitive: serde_json::Value, node: serde_json::Value) -> usize {
    let mesh = g.mesh(json!({"primitives": [primitive]}));
    let mut node = node;
    node["mesh"] = json!(mesh);
    let n = g.node(node);
    g.add_root(n);
    n
}

#[test]
fn strips_fans_non_indexed_and_quantized_positions() {
    let mut g = Gltf::new();
    // Quad as u16-normalized positions (KHR_mesh_quantization style), strip.
    let q: Vec<u16> = vec![0, 0, 0, 65535, 0, 0, 0, 65535, 0, 65535, 65535, 0];
    let pos = g.u16s(&q, "VEC3", 4);
    g.json["accessors"][pos]["normalized"] = json!(true);
    rigid(
        &mut g,
        json!({"attributes": {"POSITION": pos}, "mode": 5}),
        json!({"translation": [10.0, 0.0, 0.0]}),
    );
    // The same quad as a fan with u8 indices.
    let p = g.floats(&[0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.], "VEC3");
    let idx = g.accessor(&[0, 1, 2, 3], U8, "SCALAR", 4);
    rigid(
        &mut g,
        json!({"attributes": {"POSITION": p}, "indices": idx, "mode": 6}),
        json!({}),
    );
    // Lines are ignored.
    rigid(
        &mut g,
        json!({"attributes": {"POSITION": p}, "mode": 1}),
        json!({}),
    );
    g.json["extensionsRequired"] = json!(["KHR_mesh_quantization", "KHR_texture_transform"]);
    let imported = g.import().unwrap();
    let ext_warnings: Vec<_> = imported
        .warnings
        .iter()
        .filter(|w| w.contains("extension"))
        .collect();
    assert_eq!(ext_warnings.len(), 1, "{ext_warnings:?}");
    assert!(ext_warnings[0].contains("KHR_texture_transform"));
    let c = &imported.character;
    assert_eq!(c.vertex_count(), 8);
    assert_eq!(c.triangles.len(), 4);
    assert!(
        imported
            .warnings
            .iter()
            .any(|w| w.contains("1 point or line primitives ignored"))
    );
    let posed = c.skin(&Pose::rest(&c.skeleton));
    assert!(
        close(posed.positions[3], Vec3::new(11.0, 1.0, 0.0)),
        "rigid node transform applies"
    );
    // Both quads face +z: strip winding alternation and fan order are right.
    assert!(
        posed.normals.iter().all(|n| close(*n, Vec3::Z)),
        "{:?}",
        posed.normals
    );
}

#[test]
fn sparse_accessor_overrides_selected_elements() {
    let mut g = Gltf::new();
    let p = g.unit_triangle();
    let sparse_idx = g.accessor(&[2, 0], U16, "SCALAR", 1); // index 2 (u16), padded
    let sparse_view_idx = g.json["accessors"][sparse_idx]["bufferView"].clone();
    let sparse_val = g.floats(&[0.0, 5.0, 0.0], "VEC3");
    let sparse_view_val = g.json["accessors"][sparse_val]["bufferView"].clone();
    g.json["accessors"][p]["sparse"] = json!({
        "count": 1,
        "indices": {"bufferView": sparse_view_idx, "componentType": 5123},
        "values": {"bufferView": sparse_view_val}
    });
    rigid(&mut g, json!({"attributes": {"POSITION": p}}), json!({}));
    let c = g.import().unwrap().character;
    assert_eq!(c.positions[2], Vec3::new(0.0, 5.0, 0.0));
    assert_eq!(c.positions[1], Vec3::X);

    // A sparse index past the count is an error.
    let mut bad = g.clone();
    let off = bad.json["bufferViews"][sparse_view_idx.as_u64().unwrap() as usize]["byteOffset"]
        .as_u64()
        .unwrap() as usize;
    bad.bin[off..off + 2].copy_from_slice(&3u16.to_le_bytes());
    let err = bad.import().unwrap_err();
    assert!(err.to_string().contains("sparse.indices"), "{err}");
}

#[test]
fn morph_targets_follow_animated_weights() {
    let mut g = Gltf::new();
    let p = g.unit_triangle();
    let d = g.floats(&[0., 0., 1., 0., 0., 1., 0., 0., 1.], "VEC3");
    let mesh = g.mesh(json!({"primitives": [{"attributes": {"POSITION": p}, "targets": [{"POSITION": d}]}], "weights": [0.25]}));
    let n = g.node(json!({"mesh": mesh}));
    g.add_root(n);
    let t = g.floats(&[0.0, 1.0], "SCALAR");
    let w = g.floats(&[0.0, 1.0], "SCALAR");
    g.json["animations"] = json!([{"samplers": [{"input": t, "output": w}],
        "channels": [{"sampler": 0, "target": {"node": n, "path": "weights"}}]}]);
    let imported = g.import().unwrap();
    let c = &imported.character;
    assert_eq!(c.morph_target_count(), 1);
    let rest = c.skin(&Pose::rest(&c.skeleton));
    assert!(
        (rest.positions[0].z - 0.25).abs() < 1e-6,
        "default mesh weights apply"
    );
    let half = c.skin(&Pose::sample(&c.skeleton, &imported.clips[0], 0.5));
    assert!((half.positions[1].z - 0.5).abs() < 1e-6);
    assert_eq!(imported.clips[0].name, "animation_0");
}

#[test]
fn two_skins_rigid_nodes_and_eight_influences() {
    let mut g = util::tiny_rig();
    // A second skin over the same joints with 8 influences (two sets),
    // its weights unnormalised (sum 2) to check normalisation.
    let p = g.floats(&[0., 2., 0., 1., 2., 0., 0., 3., 0.], "VEC3");
    let j0 = g.u16s(&[0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0], "VEC4", 3);
    let w0 = g.floats(
        &[0.5, 0.5, 0., 0., 0.5, 0.5, 0., 0., 0.5, 0.5, 0., 0.],
        "VEC4",
    );
    let j1 = g.u16s(&[1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0], "VEC4", 3);
    let w1 = g.floats(&[1.0, 0., 0., 0., 1.0, 0., 0., 0., 1.0, 0., 0., 0.], "VEC4");
    let mesh = g.mesh(json!({"primitives": [{"attributes": {
        "POSITION": p, "JOINTS_0": j0, "WEIGHTS_0": w0, "JOINTS_1": j1, "WEIGHTS_1": w1}}]}));
    let ibm = g.json["skins"][0]["inverseBindMatrices"].clone();
    g.json["skins"]
        .as_array_mut()
        .unwrap()
        .push(json!({"joints": [0, 1], "inverseBindMatrices": ibm}));
    // The skinned node sits under a transformed parent: ignored, as the spec says.
    let skinned = g.node(json!({"mesh": mesh, "skin": 1}));
    let parent = g.node(json!({"translation": [100.0, 0.0, 0.0], "children": [skinned]}));
    g.add_root(parent);
    // A rigid mesh attached to joint 1.
    let rp = g.floats(&[0., 0., 0., 0.1, 0., 0., 0., 0.1, 0.], "VEC3");
    let rmesh = g.mesh(json!({"primitives": [{"attributes": {"POSITION": rp}}]}));
    let rnode = g.node(json!({"mesh": rmesh, "translation": [0.0, 1.0, 0.0]}));
    g.json["nodes"][1]["children"] = json!([rnode]);
    let imported = g.import().unwrap();
    let c = &imported.character;
    assert_eq!(c.influences, 8);
    assert_eq!(c.joints.len(), 2 + 2 + 1, "two skins and one rigid node");
    assert!(
        imported
            .warnings
            .iter()
            .any(|w| w.contains("3 vertices had skin weights not summing to 1"))
    );
    let pose = Pose::sample(&c.skeleton, &imported.clips[0], 1.0);
    let posed = c.skin(&pose);
    let first_vertex = |node: usize| {
        c.primitives
            .iter()
            .find(|p| p.node == node)
            .unwrap()
            .vertices
            .start
    };
    // Depth-first scene order: the rigid mesh under joint 1 comes first.
    assert_eq!(first_vertex(rnode), 0);
    // The second skin's first vertex (0,2,0): weights 0.25 joint 0, 0.75
    // joint 1 after normalising.
    let v = first_vertex(skinned);
    let on_joint1 = Vec3::new(-0.5, 1.5, 0.0); // (0, 0.5) about (0,1.5) rotated 90°
    let expect = 0.25 * Vec3::new(0.0, 2.0, 0.0) + 0.75 * on_joint1;
    assert!(
        close(posed.positions[v], expect),
        "{} vs {expect}",
        posed.positions[v]
    );
    // The rigid vertex at its node's origin sits at joint 1 (y=1.5) plus
    // the node's local offset (0,1,0) rotated 90°: (-1, 1.5, 0).
    let r = first_vertex(rnode);
    assert!(
        close(posed.positions[r], Vec3::new(-1.0, 1.5, 0.0)),
        "{}",
        posed.positions[r]
    );
}

#[test]
fn clips_from_a_second_file_bind_by_node_name() {
    let character = util::tiny_rig().import().unwrap();
    // A clip file: a single node named "upper", rotated 90° by step.
    let mut clipfile = Gltf::new();
    let n = clipfile.node(json!({"name": "upper"}));
    let stray = clipfile.node(json!({"name": "not-in-the-character"}));
    clipfile.add_root(n);
    clipfile.add_root(stray);
    let t = clipfile.floats(&[0.0, 0.5], "SCALAR");
    let h = std::f32::consts::FRAC_PI_4;
    let r = clipfile.floats(&[0., 0., 0., 1., 0., 0., h.sin(), h.cos()], "VEC4");
    let tr = clipfile.floats(&[0., 0., 0., 0., 0., 0.], "VEC3");
    clipfile.json["animations"] = json!([{"name": "snap", "samplers": [
        {"input": t, "output": r, "interpolation": "STEP"},
        {"input": t, "output": tr}
    ], "channels": [
        {"sampler": 0, "target": {"node": n, "path": "rotation"}},
        {"sampler": 1, "target": {"node": stray, "path": "translation"}}
    ]}]);
    let bytes = clipfile.glb();
    let (clips, warnings) = import_clips(
        Upload::single(&bytes),
        &character.character,
        &Limits::default(),
    )
    .unwrap();
    assert_eq!(clips.len(), 1);
    assert_eq!(clips[0].channels.len(), 1);
    assert_eq!(
        clips[0].channels[0].node, 1,
        "bound to the character's node named upper"
    );
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("1 animation channels target nodes"))
    );
    let c = &character.character;
    let before = c.skin(&Pose::sample(&c.skeleton, &clips[0], 0.49));
    let after = c.skin(&Pose::sample(&c.skeleton, &clips[0], 0.5));
    assert!(
        close(before.positions[7], c.positions[7]),
        "step holds the first key"
    );
    assert!(close(after.positions[7], Vec3::new(-1.5, 2.0, 0.0)));

    // A clip file that matches nothing is an error.
    let mut none = Gltf::new();
    let x = none.node(json!({"name": "x"}));
    none.add_root(x);
    let t = none.floats(&[0.0], "SCALAR");
    let tr = none.floats(&[0., 0., 0.], "VEC3");
    none.json["animations"] = json!([{"samplers": [{"input": t, "output": tr}],
        "channels": [{"sampler": 0, "target": {"node": x, "path": "translation"}}]}]);
    let err = import_clips(Upload::single(&none.glb()), c, &Limits::default()).unwrap_err();
    assert!(
        matches!(
            err,
            aobake_core::ImportError::NoAnimations { in_file: true }
        ) && err.to_string().contains("no channel targets a node name"),
        "{err}"
    );
    // One with no animations at all says that.
    let mut still = Gltf::new();
    let x = still.node(json!({"name": "x"}));
    still.add_root(x);
    let err = import_clips(Upload::single(&still.glb()), c, &Limits::default()).unwrap_err();
    assert!(
        matches!(
            err,
            aobake_core::ImportError::NoAnimations { in_file: false }
        ) && err.to_string() == "the file has no animations",
        "{err}"
    );
}

#[test]
fn cubic_spline_rotation_clip_samples_between_keys() {
    let mut g = util::tiny_rig();
    let t = g.floats(&[0.0, 1.0], "SCALAR");
    let h = std::f32::consts::FRAC_PI_4;
    // in-tangent, value, out-tangent per key; zero tangents.
    let v = g.floats(
        &[
            0.,
            0.,
            0.,
            0.,
            0.,
            0.,
            0.,
            1.,
            0.,
            0.,
            0.,
            0.,
            0.,
            0.,
            0.,
            0.,
            0.,
            0.,
            h.sin(),
            h.cos(),
            0.,
            0.,
            0.,
            0.,
        ],
        "VEC4",
    );
    g.json["animations"][0]["samplers"][0] =
        json!({"input": t, "output": v, "interpolation": "CUBICSPLINE"});
    let imported = g.import().unwrap();
    let c = &imported.character;
    let pose = Pose::sample(&c.skeleton, &imported.clips[0], 0.5);
    // Zero tangents: Hermite at s=0.5 is the midpoint of the two values,
    // normalised: a 45° rotation.
    let expect = glam::Quat::from_rotation_z(std::f32::consts::FRAC_PI_4);
    assert!(
        pose.locals[1].rotation.dot(expect).abs() > 1.0 - 1e-6,
        "{:?}",
        pose.locals[1].rotation
    );
}

#[test]
fn real_world_oddities_are_accepted() {
    let mut g = util::tiny_rig();
    // A custom attribute (Blender's custom attributes, EXT_mesh_features).
    let extra = g.floats(&[0.0; 8], "SCALAR");
    g.json["meshes"][0]["primitives"][0]["attributes"]["_FEATURE_ID_0"] = json!(extra);
    // A texture without `source` (webp/basisu through an extension).
    g.json["textures"] = json!([{"extensions": {"EXT_texture_webp": {"source": 0}}}]);
    // An all-zero accessor without bufferView, used as a morph target.
    let zeros = g.json["accessors"].as_array().unwrap().len();
    g.json["accessors"]
        .as_array_mut()
        .unwrap()
        .push(json!({"componentType": 5126, "type": "VEC3", "count": 8}));
    g.json["meshes"][0]["primitives"][0]["targets"] = json!([{"POSITION": zeros}]);
    let imported = g.import().unwrap();
    assert_eq!(imported.character.morph_target_count(), 1);
    assert!(
        imported.character.morphs[0].targets[0]
            .positions
            .iter()
            .all(|d| *d == Vec3::ZERO)
    );
    assert!(
        imported
            .warnings
            .iter()
            .any(|w| w.contains("materials, textures")),
        "{:?}",
        imported.warnings
    );
}

#[test]
fn mirrored_nodes_keep_outward_normals() {
    let mut g = Gltf::new();
    let p = g.unit_triangle();
    let n = g.floats(&[0., 0., 1., 0., 0., 1., 0., 0., 1.], "VEC3");
    rigid(
        &mut g,
        json!({"attributes": {"POSITION": p, "NORMAL": n}}),
        json!({"scale": [-1.0, 1.0, 1.0]}),
    );
    let c = g.import().unwrap().character;
    let posed = c.skin(&Pose::rest(&c.skeleton));
    // Mirroring in x leaves a +z normal pointing along +z.
    assert!(close(posed.normals[0], Vec3::Z), "{}", posed.normals[0]);
}

#[test]
fn zero_scale_node_matrix_is_accepted() {
    let mut g = Gltf::new();
    let p = g.unit_triangle();
    let mut m = glam::Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0)).to_cols_array();
    m[0] = 0.0;
    rigid(
        &mut g,
        json!({"attributes": {"POSITION": p}}),
        json!({"matrix": m}),
    );
    let c = g.import().unwrap().character;
    let posed = c.skin(&Pose::rest(&c.skeleton));
    assert!(
        close(posed.positions[1], Vec3::new(1.0, 2.0, 3.0)),
        "{}",
        posed.positions[1]
    );
}
