//! Every real character loads, with the counts of `shared/data/README.md`.

use aobake_core::summary::Summary;

use crate::util;

/// file, vertices (scene), triangles (scene), vertices (file), triangles
/// (file), skins, clips.
const EXPECTED: &[(&str, usize, usize, u64, u64, usize, usize)] = &[
    ("SimpleSkin.gltf", 10, 8, 10, 8, 1, 1),
    ("RiggedSimple.glb", 160, 188, 160, 188, 1, 1),
    ("RiggedFigure.glb", 370, 256, 370, 256, 1, 1),
    ("Fox.glb", 1728, 576, 1728, 576, 1, 3),
    ("character-female-a.glb", 1576, 876, 1576, 876, 2, 32),
    ("CesiumMan.glb", 3273, 4672, 3273, 4672, 1, 1),
    ("CesiumMilkTruck.glb", 3564, 3624, 2978, 2856, 0, 2),
    ("InterpolationTest.glb", 220, 110, 28, 14, 0, 9),
];

#[test]
fn counts_match_the_data_readme() {
    let mut seen = 0;
    for &(file, verts, tris, verts_file, tris_file, skins, clips) in EXPECTED {
        let Some(path) = util::character_path(file) else {
            eprintln!("skipped {file}: not bundled and ../shared/data is absent");
            continue;
        };
        let imported = util::load(&path);
        let s = Summary::of(&imported.character, &imported.clips);
        assert_eq!(
            (
                s.vertices,
                s.triangles,
                s.vertices_unique,
                s.triangles_unique,
                s.skins,
                s.clips.len()
            ),
            (verts, tris, verts_file, tris_file, skins, clips),
            "{file}"
        );
        assert!(s.diagonal.is_finite() && s.diagonal > 0.0, "{file}: {s:?}");
        seen += 1;
    }
    assert!(seen >= 3, "the bundled characters must always be checked");
}

#[test]
fn every_character_present_imports_and_poses_finitely() {
    for path in util::all_characters() {
        let imported = util::load(&path);
        let c = &imported.character;
        assert!(
            c.vertex_count() > 0 && !c.triangles.is_empty(),
            "{}",
            path.display()
        );
        for clip in &imported.clips {
            for t in [0.0, clip.duration * 0.5, clip.duration] {
                let posed = c.skin(&aobake_core::Pose::sample(&c.skeleton, clip, t));
                assert!(
                    posed.positions.iter().all(|p| p.is_finite()),
                    "{} {} t={t}",
                    path.display(),
                    clip.name
                );
                assert!(posed.normals.iter().all(|n| n.is_finite()));
            }
        }
    }
}

#[test]
fn fox_clip_names_and_durations() {
    let Some(path) = util::character_path("Fox.glb") else {
        return;
    };
    let imported = util::load(&path);
    let names: Vec<(&str, f32)> = imported
        .clips
        .iter()
        .map(|c| (c.name.as_str(), c.duration))
        .collect();
    assert_eq!(names.len(), 3);
    assert_eq!(names[0].0, "Survey");
    assert!((names[0].1 - 3.4166667).abs() < 1e-4, "{names:?}");
    assert_eq!(names[1].0, "Walk");
    assert_eq!(names[2].0, "Run");
}

#[test]
fn kenney_character_loads_without_its_missing_texture() {
    let Some(path) = util::character_path("character-female-a.glb") else {
        return;
    };
    let imported = util::load(&path);
    assert!(
        imported.warnings.iter().any(|w| w.contains("colormap.png")),
        "{:?}",
        imported.warnings
    );
}

#[test]
fn bind_pose_returns_the_modelled_skinned_mesh() {
    for path in util::all_characters() {
        let imported = util::load(&path);
        let c = &imported.character;
        let posed = c.skin(&aobake_core::Pose::bind(c));
        let diagonal = aobake_core::geometry::bounds(c.positions.iter().copied())
            .map_or(1.0, |(lo, hi)| (hi - lo).length());
        for prim in c.primitives.iter().filter(|p| p.skin.is_some()) {
            for v in prim.vertices.clone() {
                let error = posed.positions[v].distance(c.positions[v]);
                assert!(
                    error <= 1e-4 * diagonal,
                    "{}: vertex {v} moved by {error} in the bind pose",
                    path.display()
                );
            }
        }
    }
}
