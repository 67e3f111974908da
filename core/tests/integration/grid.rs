//! Malmer et al.'s grids as a bake: slab jobs that resume with the same
//! bytes however the grid is cut, the cone lookup against the closed form
//! of a sphere over a plane, and whole bakes in process on the milk truck
//! and the rigid robot, judged on clip frames against ray-traced truth.

use aobake_core::{
    asset::Container,
    bake::{Bake, BakeParams, GraphOptions, JobError, JobSpec, NoSink, bake_in_process},
    bake::{BakeReport, grid::GridReport},
    method::{
        Method,
        grid::{
            GridOptions, PartsMode,
            evaluate::{GroundTruth, Inputs},
            field::{self, Slab, finish, part_scene, trace_layers},
            model::{GridModel, PartGrid, Terms},
            tclip::TClip,
        },
    },
    trace::{TraceError, VolumeParams, shapes::icosphere},
};
use glam::{Mat4, Vec3};

use crate::{jobs::Interrupting, util};

/// A small grid bake: 16³ cells, 64 rays a cell, a short evaluation.
fn quick() -> BakeParams {
    let mut p = BakeParams::new(Method::Grid);
    p.grid = GridOptions {
        resolution: 16,
        rays: 64,
        tclip_resolution: 16,
        eval_frames: 4,
        eval_ground: 256,
        eval_rays: 128,
        average_frames: 8,
        ..GridOptions::default()
    };
    p
}

fn truck() -> aobake_core::Imported {
    util::load(&util::character_path("CesiumMilkTruck.glb").unwrap())
}

fn robot() -> aobake_core::Imported {
    util::load(&util::repo().join("tests/data/scenes/RigidRobot/RigidRobot.gltf"))
}

#[test]
fn a_slab_resumed_from_its_checkpoint_or_cut_otherwise_gives_the_same_cells() {
    let imported = truck();
    let inputs = util::inputs(&imported.character, &imported.clips);
    let bake = Bake::new(&inputs, quick()).unwrap();
    assert_eq!(bake.grid_parts().unwrap().len(), 3, "body and two axles");
    let spec = JobSpec::Slab {
        part: 1,
        first: 4,
        count: 4,
    };
    let whole = bake.run_job(&spec, &[], None, &mut NoSink).unwrap();
    let bytes = whole.get("slab-1-4").unwrap();
    for stop_after in 1..=3 {
        let mut first = Interrupting {
            stop_after: Some(stop_after),
            ..Default::default()
        };
        let err = bake.run_job(&spec, &[], None, &mut first).unwrap_err();
        assert!(matches!(err, JobError::Stopped(_)), "{err}");
        let last = first.saved.pop().unwrap();
        assert_eq!(
            (last.step.as_str(), last.cursor),
            ("slab", stop_after as u64)
        );
        let mut next = Interrupting::default();
        let resumed = bake.run_job(&spec, &[], Some(last), &mut next).unwrap();
        assert_eq!(next.progress[0], (stop_after as u64, 4));
        assert_eq!(
            resumed.get("slab-1-4"),
            Some(bytes),
            "stopped after {stop_after}"
        );
    }
    // Cut in two slabs of two layers, the same cells.
    let mut cells = Vec::new();
    for first in [4, 6] {
        let spec = JobSpec::Slab {
            part: 1,
            first,
            count: 2,
        };
        let out = bake.run_job(&spec, &[], None, &mut NoSink).unwrap();
        let slab = Slab::from_bytes(out.get(&format!("slab-1-{first}")).unwrap(), 16).unwrap();
        cells.extend(slab.cells);
    }
    assert_eq!(Slab::from_bytes(bytes, 16).unwrap().cells, cells);
    // A slab of another bake's shape is refused by name.
    let bad = JobSpec::Slab {
        part: 3,
        first: 0,
        count: 4,
    };
    let e = bake.run_job(&bad, &[], None, &mut NoSink).unwrap_err();
    assert!(e.to_string().contains("not a slab of this bake"), "{e}");
}

/// The ground under a sphere of radius r whose centre is at height d has
/// A = (r/d)² (DESIGN §4). The sphere's cone seen from the ground is a cap
/// of half-angle asin(r/d): T_clip at β = 0 gives sin²θ, exactly A, while
/// the plain ×2 rule gives 1 − √(1 − (r/d)²), half of it when small.
#[test]
fn the_cone_lookup_gives_the_sphere_over_a_plane_and_the_plain_rule_half() {
    let ball = icosphere(4, 1.0, Vec3::ZERO);
    let scene = part_scene(&ball.positions, &ball.triangles).unwrap();
    // A tiny ε: a grid wide enough that the boundary rescale barely
    // touches the values looked up.
    let grid = field::around(&ball.positions, 0.005, 48);
    let mut cells = Vec::new();
    trace_layers::<TraceError>(
        &scene,
        &grid,
        0,
        0..48,
        VolumeParams {
            samples: 1024,
            max_distance: f32::INFINITY,
            seed: 7,
        },
        &mut |_, c| {
            cells.extend(c);
            Ok(())
        },
    )
    .unwrap();
    let model = |cones: bool| {
        let f = finish(&cells, 48, cones);
        assert!(f.inside > 0 && f.boundary_max < 0.02, "{}", f.boundary_max);
        GridModel {
            parts: vec![PartGrid {
                name: "ball".into(),
                joint: 0,
                node: 0,
                grid,
                boundary_max: f.boundary_max,
                inside: f.inside,
                occlusion: f.occlusion,
                directions: f.directions,
            }],
            tclip: cones.then(|| TClip::compute(64)),
            base: None,
        }
    };
    let (cones, plain) = (model(true), model(false));
    let poses = cones.poses(&[Mat4::IDENTITY]);
    for d in [1.5f32, 2.0, 3.0] {
        let ground = Vec3::new(0.0, -d, 0.0);
        let exact = (1.0 / d).powi(2);
        let with = cones.occlusion(&poses, ground, Vec3::Y, None, Terms::All);
        let without = plain.occlusion(&poses, ground, Vec3::Y, None, Terms::All);
        let half_rule = 1.0 - (1.0 - exact).sqrt();
        eprintln!(
            "d = {d}: exact {exact:.4}, cones {with:.4}, plain {without:.4} (rule {half_rule:.4})"
        );
        assert!(
            (with - exact).abs() < 0.03,
            "d = {d}: cones {with} against {exact}"
        );
        assert!(
            (without - half_rule).abs() < 0.03,
            "d = {d}: plain {without} against {half_rule}"
        );
    }
    // Off to the side, the tangent plane clips the cone: a receiver level
    // with the centre, facing up, sees the ball's upper half only.
    let side = Vec3::new(2.0, 0.0, 0.0);
    let with = cones.occlusion(&poses, side, Vec3::Y, None, Terms::All);
    let facing = cones.occlusion(&poses, side, -Vec3::X, None, Terms::All);
    assert!(with < 0.6 * facing, "{with} {facing}");
}

fn report(baked: &aobake_core::bake::Baked) -> &GridReport {
    match &baked.report {
        BakeReport::Grid(r) => r,
        _ => panic!("a grid bake gave another report"),
    }
}

#[test]
fn grids_bake_in_process_and_beat_no_occlusion_between_parts_on_unseen_frames() {
    for (name, imported) in [("CesiumMilkTruck", truck()), ("RigidRobot", robot())] {
        let inputs = util::inputs(&imported.character, &imported.clips);
        for cones in [true, false] {
            let mut params = quick();
            params.grid.cones = cones;
            let bake = Bake::new(&inputs, params).unwrap();
            let graph = bake.graph(GraphOptions {
                previews: false,
                ..GraphOptions::default()
            });
            let parts = bake.grid_parts().unwrap().len();
            let count = |kind: &str| graph.jobs.iter().filter(|j| j.spec.kind() == kind).count();
            assert_eq!(count("slab"), 2 * parts, "two slabs of 8 per part");
            assert!(count("sample") >= 1, "the static base's frames");
            assert_eq!(graph.jobs.len(), count("slab") + count("sample") + 2);
            let baked = bake_in_process(&bake, None).unwrap();
            let r = report(&baked);
            let container = Container::from_bytes(&baked.asset).unwrap();
            let (model, header) = GridModel::from_container(&container).unwrap();
            assert_eq!((header.cones, model.parts.len()), (cones, parts));
            assert_eq!(r.sizes.asset_bytes, baked.asset.len());
            // The rays it counts are the rays the service bounds.
            assert_eq!(
                u128::from(r.rays),
                bake.plan
                    .params
                    .grid
                    .rays_total(parts, imported.character.vertex_count())
            );
            assert_eq!(
                r.parts
                    .iter()
                    .map(|p| p.bytes[usize::from(!cones)])
                    .sum::<usize>(),
                model.parts.iter().map(PartGrid::bytes).sum::<usize>()
            );
            let v = &r.evaluation.variants;
            let get = |n: &str| {
                v.iter()
                    .find(|x| x.name == n)
                    .unwrap_or_else(|| panic!("no variant {n}"))
            };
            let first = if cones {
                "grids on a static base (cones)"
            } else {
                "grids on a static base"
            };
            assert_eq!(v[0].name, first, "the baked variant first");
            assert_eq!(v[0].bytes, model.bytes());
            let base = model
                .base
                .as_ref()
                .expect("the default bakes a static base");
            assert_eq!(base.vertex_offsets.len(), imported.character.vertex_count());
            // Every variant shades the ground better than nothing; at the
            // parts' vertices the cones do, while the plain ×2 rule, blind
            // to the receiver's normal, darkens faces turned away from the
            // other parts too (the truck's wheels in their wells): it is
            // reported, not required.
            for (grids, alone, at_vertices) in [
                ("grids", "own grid only", false),
                ("grids (cones)", "own grid only (cones)", true),
                ("traced self + grids", "traced self only", false),
                ("traced self + grids (cones)", "traced self only", true),
            ] {
                let (g, a) = (get(grids), get(alone));
                eprintln!(
                    "{name}: {grids}: vertices RMSE {:.4} ground {:.4}; {alone}: {:.4} {:.4}",
                    g.vertices.mean.rmse,
                    g.ground.mean.rmse,
                    a.vertices.mean.rmse,
                    a.ground.mean.rmse
                );
                assert!(
                    g.ground.mean.rmse < a.ground.mean.rmse,
                    "{name}: {grids} shade the ground better than nothing"
                );
                assert!(
                    !at_vertices || g.vertices.mean.rmse < a.vertices.mean.rmse,
                    "{name}: {grids} beat {alone} at the parts' vertices"
                );
            }
            // The cones beat the plain rule at the vertices, where the
            // receiver's normal matters.
            assert!(
                get("grids (cones)").vertices.mean.rmse < get("grids").vertices.mean.rmse,
                "{name}: the cones beat the plain ×2 rule"
            );
            let average = get("static average");
            eprintln!(
                "{name}: static average: vertices RMSE {:.4} ground {:.4}; noise {:.4} {:.4}",
                average.vertices.mean.rmse,
                average.ground.mean.rmse,
                r.evaluation.noise_rmse_vertices,
                r.evaluation.noise_rmse_ground
            );
            // The product beats the static average at the vertices and on
            // the ground, on frames it never saw.
            let product = &v[0];
            eprintln!(
                "{name}: {first}: vertices RMSE {:.4} ground {:.4}",
                product.vertices.mean.rmse, product.ground.mean.rmse,
            );
            assert!(
                product.vertices.mean.rmse < average.vertices.mean.rmse,
                "{name}: {first} beats the static average at the vertices"
            );
            assert!(
                product.ground.mean.rmse < average.ground.mean.rmse,
                "{name}: {first} beats the static average on the ground"
            );
            assert!(baked.plot.starts_with(b"\x89PNG"));
        }
    }
}

#[test]
fn a_skinned_character_has_no_rigid_parts_but_has_joint_parts() {
    let imported = util::load(&util::character_path("CesiumMan.glb").unwrap());
    let inputs = util::inputs(&imported.character, &imported.clips);
    let e = Bake::new(&inputs, quick()).unwrap_err().to_string();
    assert!(e.contains("grid.parts = joints"), "{e}");
    let mut params = quick();
    params.grid.parts = PartsMode::Joints;
    let bake = Bake::new(&inputs, params).unwrap();
    let parts = bake.grid_parts().unwrap();
    assert!(parts.len() > 10, "{}", parts.len());
    let vertices: usize = parts.iter().map(|p| p.vertices.len()).sum();
    assert_eq!(vertices, imported.character.vertex_count());
}

/// The evaluation's static average takes the training frames' truth at
/// the vertices from the static base's `sample` jobs, which traced it
/// with the same function and seed, instead of tracing it again: the same
/// values bit for bit, and that many rays fewer.
#[test]
fn the_evaluation_reuses_the_sample_jobs_vertex_truth_with_the_same_values() {
    let truck = truck();
    let params = quick();
    let o = &params.grid;
    let parts = aobake_core::method::grid::parts::parts(&truck.character, o.parts).unwrap();
    let inputs = Inputs {
        character: &truck.character,
        clips: &truck.clips,
        train: &[0],
        test: &[0],
        parts: &parts,
        options: o,
        max_distance: o.distance(&truck.character, &parts),
        seed: 11,
    };
    let frames = inputs.training_frames();
    // What the `sample` jobs hand over: the frames at the vertices (and
    // at the base's texels, which the evaluation does not use).
    let known: Vec<f32> = inputs
        .trace_frames(&frames, &[Vec3::ZERO])
        .unwrap()
        .into_iter()
        .flat_map(|v| v.vertices)
        .collect();
    let fresh = GroundTruth::trace(&inputs, None).unwrap();
    let reused = GroundTruth::trace(&inputs, Some(&known)).unwrap();
    assert_eq!(fresh.average, reused.average, "the static average");
    assert_eq!(fresh.self_ao, reused.self_ao);
    assert_eq!(fresh.noise_rmse, reused.noise_rmse);
    for (a, b) in fresh.frames.iter().zip(&reused.frames) {
        assert_eq!((&a.vertices, &a.ground), (&b.vertices, &b.ground));
    }
    let vertices = truck.character.vertex_count() as u64;
    assert_eq!(
        fresh.rays - reused.rays,
        frames.len() as u64 * vertices * u64::from(o.eval_rays),
        "the training frames' vertices are not traced again"
    );
    assert!(fresh.average.0.iter().any(|&a| a > 0.0));
}
