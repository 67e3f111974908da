//! Pose parameters: joint angles both ways, ranges from clips, handles,
//! seeded samplers.

use aobake_core::{
    Pose,
    pose_space::{self, LayoutOptions, clip_frames, random_clip_frames},
};

use crate::util;

fn characters_with_clips() -> Vec<aobake_core::Imported> {
    util::all_characters()
        .iter()
        .map(|p| util::load(p))
        .filter(|i| !i.clips.is_empty())
        .collect()
}

#[test]
fn joint_angles_round_trip_through_clip_poses() {
    for imported in characters_with_clips() {
        let c = &imported.character;
        let Ok(layout) = pose_space::joint_angles(c, &imported.clips, LayoutOptions::default())
        else {
            continue;
        };
        for clip in &imported.clips {
            let pose = Pose::sample(&c.skeleton, clip, clip.duration * 0.37);
            let params = layout.params(&c.skeleton, &pose.locals);
            let back = pose_space::pose(&layout, &c.skeleton, &params).unwrap();
            for &j in &layout.joints {
                let (a, b) = (pose.locals[j].rotation, back.locals[j].rotation);
                assert!(a.dot(b).abs() > 1.0 - 1e-5, "{}: joint {j}", clip.name);
            }
            // Parameters of a clip frame lie inside the ranges.
            for ((v, r), name) in params.iter().zip(&layout.ranges).zip(&layout.names) {
                assert!(
                    *v >= r.min - 1e-5 && *v <= r.max + 1e-5,
                    "{name}: {v} not in {r:?}"
                );
            }
        }
    }
}

#[test]
fn joint_angle_pose_reproduces_the_skinned_mesh() {
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let c = &imported.character;
    let options = LayoutOptions {
        root_translation: true,
        ..LayoutOptions::default()
    };
    let layout = pose_space::joint_angles(c, &imported.clips, options).unwrap();
    // The body root's translation moves the whole mesh and changes no AO:
    // never a parameter; RiggedFigure's other translation channels hold
    // their rest offsets, so none is one.
    assert!(layout.translations.is_empty(), "{:?}", layout.translations);
    // The parameters carry the whole pose up to the body root's motion.
    let clip = &imported.clips[0];
    let pose = Pose::sample(&c.skeleton, clip, 0.6);
    let direct = c.skin(&pose);
    let via = c.skin(
        &pose_space::pose(
            &layout,
            &c.skeleton,
            &layout.params(&c.skeleton, &pose.locals),
        )
        .unwrap(),
    );
    let centre = |p: &[glam::Vec3]| p.iter().copied().sum::<glam::Vec3>() / p.len() as f32;
    let (ca, cb) = (centre(&direct.positions), centre(&via.positions));
    let worst = direct
        .positions
        .iter()
        .zip(&via.positions)
        .map(|(a, b)| (*a - ca).distance(*b - cb))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "worst {worst}");
}

#[test]
fn uniform_sampler_is_seeded_and_stays_in_range() {
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let c = &imported.character;
    let layout = pose_space::joint_angles(c, &imported.clips, LayoutOptions::default()).unwrap();
    let a = pose_space::sample_uniform(&layout, 50, 7);
    assert_eq!(a, pose_space::sample_uniform(&layout, 50, 7));
    assert_ne!(a, pose_space::sample_uniform(&layout, 50, 8));
    for params in &a {
        for (v, r) in params.iter().zip(&layout.ranges) {
            assert!(*v >= r.min && *v <= r.max);
        }
        let posed = c.skin(&pose_space::pose(&layout, &c.skeleton, params).unwrap());
        assert!(posed.positions.iter().all(|p| p.is_finite()));
    }
    assert!(pose_space::pose(&layout, &c.skeleton, &[0.0]).is_err());
}

#[test]
fn handles_are_root_relative_and_move_with_the_pose() {
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let c = &imported.character;
    let handles = pose_space::handles(c);
    assert_eq!(handles.len(), 6 * 19);
    let rest = handles.handles(&c.skeleton, &c.skeleton.rest_locals());
    // The body root is a joint here, at the origin of its own frame.
    let body = c.body_root().unwrap();
    assert_eq!(handles.root, Some(body));
    let root = handles.joints.iter().position(|&j| j == body).unwrap();
    assert!(rest[6 * root..6 * root + 3].iter().all(|x| x.abs() < 1e-6));
    // Off-axis handles are not on the joint.
    for k in 0..handles.joints.len() {
        let (a, b) = (&rest[6 * k..6 * k + 3], &rest[6 * k + 3..6 * k + 6]);
        let d: f32 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
        assert!(d > 0.0, "joint {k}");
    }
    let moved = handles.handles(
        &c.skeleton,
        &Pose::sample(&c.skeleton, &imported.clips[0], 0.6).locals,
    );
    assert_ne!(rest, moved);
    // Turning and moving the whole character changes no handle.
    let mut turned = Pose::sample(&c.skeleton, &imported.clips[0], 0.6);
    let top = (0..c.skeleton.nodes.len())
        .find(|&n| c.skeleton.nodes[n].parent.is_none() && c.skeleton.is_ancestor_or_self(n, body))
        .unwrap();
    turned.locals[top].rotation = glam::Quat::from_rotation_y(1.0) * turned.locals[top].rotation;
    turned.locals[top].translation += glam::Vec3::new(3.0, -1.0, 2.0);
    let after = handles.handles(&c.skeleton, &turned.locals);
    for (a, b) in after.iter().zip(&moved) {
        assert!((a - b).abs() < 1e-4, "{a} vs {b}");
    }
}

#[test]
fn clip_frame_samplers() {
    let imported = util::load(&util::character_path("RiggedSimple.glb").unwrap());
    let frames = clip_frames(&imported.clips, 24.0);
    assert_eq!(frames.first().unwrap().time, 0.0);
    assert_eq!(frames.last().unwrap().time, imported.clips[0].duration);
    let random = random_clip_frames(&imported.clips, 20, 3);
    assert_eq!(random, random_clip_frames(&imported.clips, 20, 3));
    assert!(
        random
            .iter()
            .all(|f| f.time >= 0.0 && f.time <= imported.clips[0].duration)
    );
}

#[test]
fn animated_scales_are_pose_parameters_down_to_zero() {
    // Three of InterpolationTest's clips only scale a cube, down to 0.
    let imported = util::load(&util::character_path("InterpolationTest.glb").unwrap());
    let c = &imported.character;
    let without = pose_space::joint_angles(
        c,
        &imported.clips,
        LayoutOptions {
            scales: false,
            ..LayoutOptions::default()
        },
    )
    .unwrap();
    let layout = pose_space::joint_angles(c, &imported.clips, LayoutOptions::default()).unwrap();
    assert!(without.scales.is_empty());
    assert_eq!(layout.scales.len(), 3, "{:?}", layout.names);
    assert_eq!(layout.len(), without.len() + 9);
    assert!(layout.names.iter().any(|n| n.ends_with(".sx")));
    // Scale over rest minus 1: a cube scaled to nothing is −1; at rest 0.
    // The margin widens each range (the clips scale between 0 and 1, so
    // the top goes to 1.1) but does not take a scale through zero, which
    // would turn the cube inside out.
    let first_scale = 3 * (layout.joints.len() + layout.translations.len());
    for r in &layout.ranges[first_scale..] {
        assert_eq!(r.min, -1.0, "{r:?}");
        assert!((r.max - 0.1).abs() < 1e-4, "{r:?}");
    }
    // The rotations' ranges are still widened below the clips' half turn.
    assert!(
        layout.ranges[..first_scale]
            .iter()
            .any(|r| r.min < -std::f32::consts::PI - 0.2),
        "{:?}",
        &layout.ranges[..first_scale]
    );
    let rest = Pose::rest(&c.skeleton);
    assert!(
        layout.params(&c.skeleton, &rest.locals)[first_scale..]
            .iter()
            .all(|&x| x == 0.0)
    );
    // Every clip's frames survive params → pose → params, scales included,
    // and the posed mesh is the clip's.
    for clip in &imported.clips {
        for t in [0.3f32, 0.9, 1.5] {
            let pose = Pose::sample(&c.skeleton, clip, t);
            let params = layout.params(&c.skeleton, &pose.locals);
            let back = pose_space::pose(&layout, &c.skeleton, &params).unwrap();
            let again = layout.params(&c.skeleton, &back.locals);
            for (a, b) in params.iter().zip(&again) {
                assert!((a - b).abs() < 1e-5, "{}: {a} vs {b}", clip.name);
            }
            let (direct, via) = (c.skin(&pose), c.skin(&back));
            let worst = direct
                .positions
                .iter()
                .zip(&via.positions)
                .map(|(a, b)| a.distance(*b))
                .fold(0.0f32, f32::max);
            assert!(worst < 1e-4, "{} at {t}: {worst}", clip.name);
        }
    }
}
