//! Damaged and hostile assets: an engine (`aobake-runtime`, its C ABI) and
//! aobake itself (`aobake eval`, `inspect`, previews) read assets they did
//! not write. Checksums catch damage in transit, so these assets are
//! mutated *inside* the container and sealed again with valid checksums,
//! as a buggy or hostile writer would make them: header numbers set to
//! extremes, keys dropped, arrays cut, section elements set to NaN,
//! infinities and extreme integers, sections cut, lengthened, dropped,
//! swapped or renamed, the method changed. Each must be refused with an
//! error or read and evaluated without a panic, at any point and pose,
//! giving occlusion in [0, 1].

use std::panic::{AssertUnwindSafe, catch_unwind};

use aobake_core::{
    Character, Clip, Pose,
    asset::{Container, Data, Section},
    bake::{Bake, BakeParams, BakedAsset, bake_in_process},
    method::{
        Method,
        cubemap::{ContinuousLayout, CubemapOptions},
        grid::{GridOptions, base::Receiver, model::GridModel},
    },
};
use aobake_runtime::{Asset, rig::Transform};
use glam::{Mat4, Quat, Vec3};
use rand::{RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;
use serde_json::Value;

use super::util;

/// A bake of `file` (a bundled character) with small settings (a
/// continuous cubemap in Kroon's thirds layout with `thirds`).
fn bake(file: &str, method: Method, thirds: bool) -> (Vec<u8>, Character, Vec<Clip>) {
    let imported = util::load(&util::repo().join("tests/data/characters").join(file));
    let mut p = BakeParams::new(method);
    p.poses = 24;
    p.samples = 8;
    p.eval_poses = 2;
    p.eval_folds = 2;
    p.clustered.pose_clusters = 2;
    p.cubemap = CubemapOptions {
        resolution: 4,
        shells: 2,
        times: 6,
        rays: 4,
        eval_points: 8,
        eval_ground: 8,
        eval_rays: 4,
        eval_times: 2,
        ground_resolution: 8,
        continuous_layout: if thirds {
            ContinuousLayout::Thirds
        } else {
            ContinuousLayout::Cosine
        },
        ..CubemapOptions::default()
    };
    p.grid = GridOptions {
        resolution: 4,
        rays: 8,
        tclip_resolution: 4,
        eval_frames: 1,
        eval_ground: 8,
        eval_rays: 4,
        average_frames: 2,
        ground_resolution: 8,
        ..GridOptions::default()
    };
    let inputs = util::inputs(&imported.character, &imported.clips);
    let baked = bake_in_process(&Bake::new(&inputs, p).unwrap(), None).unwrap();
    (baked.asset, imported.character, imported.clips)
}

/// Values a mutated JSON number or element takes.
const NUMBERS: [f64; 12] = [
    0.0,
    1.0,
    -1.0,
    0.5,
    3.0,
    255.0,
    65_536.0,
    4_294_967_297.0,
    1e30,
    -1e30,
    1e-40,
    -0.0,
];

/// Strings a mutated JSON leaf takes: the names the headers spell.
const WORDS: [&str; 14] = [
    "discrete",
    "continuous",
    "thirds",
    "cosine",
    "matrix",
    "rotation-vector",
    "vertex-linear",
    "vertex-clustered",
    "static-average",
    "grid",
    "cubemap-discrete",
    "",
    "Hips",
    "\u{0}",
];

const FLOATS: [f32; 9] = [
    f32::NAN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    1e30,
    -1e30,
    0.0,
    -1.0,
    2.0,
    1e-42,
];

fn pick<T: Clone>(from: &[T], rng: &mut ChaCha8Rng) -> T {
    from[rng.random_range(0..from.len())].clone()
}

/// Every leaf of `v`, as JSON pointers.
fn leaves(v: &Value, at: String, out: &mut Vec<String>) {
    match v {
        Value::Object(m) => {
            out.push(at.clone());
            for (k, x) in m {
                leaves(x, format!("{at}/{k}"), out);
            }
        }
        Value::Array(a) => {
            out.push(at.clone());
            for (i, x) in a.iter().enumerate() {
                leaves(x, format!("{at}/{i}"), out);
            }
        }
        _ => out.push(at),
    }
}

/// One mutation of `c`, described.
fn mutate(c: &mut Container, rng: &mut ChaCha8Rng) -> String {
    match rng.random_range(0..10) {
        0..=3 => {
            let mut header: Value = serde_json::from_str(&c.header).unwrap();
            let mut paths = Vec::new();
            leaves(&header, String::new(), &mut paths);
            let path = pick(&paths, rng);
            let what = match rng.random_range(0..7) {
                6 => {
                    let word = pick(&WORDS, rng);
                    *header.pointer_mut(&path).unwrap() = serde_json::json!(word);
                    format!("{word:?}")
                }
                0 | 1 => {
                    let x = pick(&NUMBERS, rng);
                    *header.pointer_mut(&path).unwrap() = serde_json::json!(x);
                    format!("{x}")
                }
                2 => {
                    let x = rng.random_range(0..40u64);
                    *header.pointer_mut(&path).unwrap() = serde_json::json!(x);
                    format!("{x}")
                }
                3 => {
                    let (parent, key) = path.rsplit_once('/').unwrap_or(("", ""));
                    match header.pointer_mut(parent) {
                        Some(Value::Object(m)) => {
                            m.remove(key);
                        }
                        Some(Value::Array(a)) => {
                            a.pop();
                        }
                        _ => {}
                    }
                    "removed".into()
                }
                4 => match header.pointer_mut(&path) {
                    Some(Value::Array(a)) if !a.is_empty() => {
                        let first = a[0].clone();
                        a.push(first);
                        "longer".into()
                    }
                    Some(x) => {
                        *x = Value::Null;
                        "null".into()
                    }
                    None => "nothing".into(),
                },
                _ => {
                    *header.pointer_mut(&path).unwrap() = serde_json::json!([]);
                    "[]".into()
                }
            };
            c.header = header.to_string();
            format!("header {path} = {what}")
        }
        4..=6 => {
            let k = rng.random_range(0..c.sections.len().max(1));
            let Some(s) = c.sections.get_mut(k) else {
                return "no section".into();
            };
            let tag = String::from_utf8_lossy(&s.tag).into_owned();
            let n = s.data.len();
            if n == 0 {
                return format!("{tag} is empty");
            }
            let i = rng.random_range(0..n);
            let f = pick(&FLOATS, rng);
            let big = rng.random_bool(0.5);
            match &mut s.data {
                Data::F16(v) => v[i] = half::f16::from_f32(f),
                Data::F32(v) => v[i] = f,
                Data::U8(v) => v[i] = if big { u8::MAX } else { rng.random() },
                Data::U16(v) => v[i] = if big { u16::MAX } else { rng.random() },
                Data::U32(v) => {
                    v[i] = if big {
                        u32::MAX
                    } else {
                        rng.random_range(0..70_000)
                    }
                }
            }
            format!("{tag}[{i}] = {f} or an extreme")
        }
        7 => {
            let k = rng.random_range(0..c.sections.len().max(1));
            let Some(s) = c.sections.get_mut(k) else {
                return "no section".into();
            };
            let tag = String::from_utf8_lossy(&s.tag).into_owned();
            let n = s.data.len();
            let keep = rng.random_range(0..=n);
            let grow = rng.random_bool(0.3);
            fn resize<T: Clone + Default>(v: &mut Vec<T>, keep: usize, grow: bool) {
                if grow {
                    let extra = v.len().max(1);
                    v.extend(std::iter::repeat_n(T::default(), extra));
                } else {
                    v.truncate(keep);
                }
            }
            match &mut s.data {
                Data::F16(v) => resize(v, keep, grow),
                Data::F32(v) => resize(v, keep, grow),
                Data::U8(v) => resize(v, keep, grow),
                Data::U16(v) => resize(v, keep, grow),
                Data::U32(v) => resize(v, keep, grow),
            }
            format!("{tag} resized from {n} to {}", s.data.len())
        }
        8 => {
            let n = c.sections.len();
            if n == 0 {
                return "no section".into();
            }
            let k = rng.random_range(0..n);
            match rng.random_range(0..3) {
                0 => {
                    let s = c.sections.remove(k);
                    format!("{} dropped", String::from_utf8_lossy(&s.tag))
                }
                1 => {
                    let j = rng.random_range(0..n);
                    let (a, b) = (c.sections[k].tag, c.sections[j].tag);
                    c.sections[k].tag = b;
                    c.sections[j].tag = a;
                    "two tags swapped".into()
                }
                _ => {
                    let s: Section = c.sections[k].clone();
                    c.sections.push(s);
                    "a section repeated".into()
                }
            }
        }
        _ => {
            let m = pick(&Method::ALL, rng);
            c.method = m;
            format!("method {m}")
        }
    }
}

/// Reads `bytes` as every reader does and evaluates what reads, checking
/// that occlusion stays in [0, 1] (or is refused).
fn read_and_evaluate(bytes: &[u8], character: &Character, clips: &[Clip]) -> Result<(), String> {
    let unit = |what: &str, v: f32| {
        if (0.0..=1.0).contains(&v) {
            Ok(())
        } else {
            Err(format!("{what} gave {v}"))
        }
    };
    if let Ok(asset) = Asset::from_bytes(bytes) {
        match asset {
            Asset::Vertex(mut ao) => {
                for v in ao.evaluate() {
                    unit("a vertex asset at rest", v)?;
                }
                let n = ao.skeleton().nodes.len();
                for node in 0..n.min(8) {
                    let mut t: Transform = ao.skeleton().nodes[node].rest;
                    t.rotation = Quat::from_rotation_y(2.5) * t.rotation;
                    t.translation += Vec3::splat(1e3);
                    ao.set_local(node, t);
                }
                ao.set_local(usize::MAX, Transform::IDENTITY);
                for v in ao.evaluate() {
                    unit("a vertex asset far from rest", v)?;
                }
            }
            Asset::Texel { model, header } => {
                // Its texels found again from its UVs (as a preview does):
                // an error or the atlas, at a bounded cost.
                let _ = aobake_core::method::texel::atlas::TexelAtlas::from_layout(&model.atlas);
                if let Some(rig) = &header.rig {
                    let rest: Vec<Transform> = rig.nodes.iter().map(|n| n.rest).collect();
                    let values = model.model.evaluate(rig, &rest);
                    for v in model.atlas.image(&values) {
                        unit("a texel asset's texture at rest", v)?;
                    }
                }
            }
            Asset::Cubemap { model, .. } => {
                let s = model.layout.spheroid;
                for t in [0.0, 0.3, -5.0, 1e9] {
                    let phase = model.layout.phase(t);
                    for p in [
                        s.centre,
                        s.centre + s.radii * 0.5,
                        s.centre - Vec3::Y * s.radii.y,
                        Vec3::splat(1e6),
                    ] {
                        unit("a cubemap", model.occlusion(p, phase))?;
                        unit("a cubemap's ground", model.ground_ao(p, phase))?;
                    }
                    // A NaN from the engine may give NaN, but no panic.
                    model.occlusion(Vec3::NAN, phase);
                    model.ground_ao(Vec3::NAN, phase);
                }
                model.occlusion(s.centre, model.layout.phase(f32::NAN));
            }
            Asset::Grid { model, .. } => evaluate_grid(&model, character.vertex_count())?,
        }
    }
    // aobake's own reader (eval, previews), with the character.
    if let Ok(container) = Container::from_bytes(bytes)
        && let Ok(baked) = BakedAsset::read(&container, Some(character))
    {
        let pose = match clips.first() {
            Some(clip) => Pose::sample(&character.skeleton, clip, 0.4),
            None => Pose::bind(character),
        };
        let mesh = character.skin(&pose);
        if let Ok(values) = baked.vertex_ao(character, &pose, &mesh) {
            for v in values {
                unit("aobake eval", v)?;
            }
        }
    }
    Ok(())
}

fn evaluate_grid(model: &GridModel, vertices: usize) -> Result<(), String> {
    let joints = 64;
    if model.check_palette(joints).is_err() {
        return Ok(());
    }
    let palette = vec![Mat4::from_rotation_z(0.4); joints];
    let poses = model.poses(&palette);
    model.ao(&poses, Vec3::NAN, Vec3::Y, Receiver::Ground);
    for p in [Vec3::ZERO, Vec3::splat(0.2), Vec3::splat(1e6)] {
        for receiver in [
            Receiver::Ground,
            Receiver::Other { part: Some(0) },
            Receiver::Vertex {
                index: 0,
                part: Some(0),
            },
            Receiver::Vertex {
                index: vertices.saturating_sub(1),
                part: Some(model.parts.len()),
            },
            Receiver::Vertex {
                index: usize::MAX,
                part: None,
            },
        ] {
            let v = model.ao(&poses, p, Vec3::Y, receiver);
            if !(0.0..=1.0).contains(&v) {
                return Err(format!("a grid gave {v} at {p} for {receiver:?}"));
            }
        }
    }
    Ok(())
}

#[test]
fn assets_mutated_inside_valid_checksums_are_refused_or_read_safely() {
    // More, or others: AOBAKE_MUTATIONS=20000 AOBAKE_MUTATION_SEED=7.
    let env = |name: &str, default: u64| {
        std::env::var(name)
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(default)
    };
    let iterations = env("AOBAKE_MUTATIONS", 400) as usize;
    let seed = env("AOBAKE_MUTATION_SEED", 0);
    let seeds = [
        (
            "RiggedFigure/RiggedFigure.glb",
            Method::StaticAverage,
            false,
        ),
        ("RiggedFigure/RiggedFigure.glb", Method::VertexLinear, false),
        (
            "RiggedFigure/RiggedFigure.glb",
            Method::VertexClustered,
            false,
        ),
        (
            "RiggedSimple/RiggedSimple.glb",
            Method::CubemapDiscrete,
            false,
        ),
        (
            "RiggedSimple/RiggedSimple.glb",
            Method::CubemapContinuous,
            false,
        ),
        (
            "RiggedSimple/RiggedSimple.glb",
            Method::CubemapContinuous,
            true,
        ),
        ("CesiumMilkTruck/CesiumMilkTruck.glb", Method::Grid, false),
    ];
    let mut failures = Vec::new();
    let mut accepted = 0;
    for (file, method, thirds) in seeds {
        let (asset, character, clips) = bake(file, method, thirds);
        read_and_evaluate(&asset, &character, &clips).expect("the unmutated asset");
        let original = Container::from_bytes(&asset).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(
            seed << 16 | u64::from(method.code()) << 1 | u64::from(thirds),
        );
        for i in 0..iterations {
            let mut c = original.clone();
            let what: Vec<String> = (0..rng.random_range(1..=3))
                .map(|_| mutate(&mut c, &mut rng))
                .collect();
            let bytes = c.to_bytes();
            accepted += usize::from(Asset::from_bytes(&bytes).is_ok());
            let outcome = catch_unwind(AssertUnwindSafe(|| {
                read_and_evaluate(&bytes, &character, &clips)
            }));
            let failure = match outcome {
                Ok(Ok(())) => continue,
                Ok(Err(e)) => e,
                Err(panic) => panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default(),
            };
            let name = if thirds {
                "cubemap-continuous (thirds)"
            } else {
                method.name()
            };
            failures.push(format!("{name} #{i} ({}): {failure}", what.join("; ")));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} mutated assets failed ({accepted} read), the first:\n{}",
        failures.len(),
        seeds.len() * iterations,
        failures[..failures.len().min(20)].join("\n")
    );
    // The mutations reach the readers' checks (some are harmless, such as
    // a changed generator or parameter, and read), not only the parser's.
    assert!(
        accepted > 0 && accepted < seeds.len() * iterations,
        "{accepted}"
    );
}

#[test]
fn a_degenerate_pose_gives_numbers() {
    // Every node scaled to zero: the body root's frame, which
    // vertex-clustered measures its handles in, has no inverse; and
    // translations at the edge of f32.
    for method in [Method::VertexLinear, Method::VertexClustered] {
        let (asset, _, _) = bake("RiggedFigure/RiggedFigure.glb", method, false);
        let Asset::Vertex(mut ao) = Asset::from_bytes(&asset).unwrap() else {
            panic!("a vertex asset");
        };
        for degenerate in [
            |t: &mut Transform| t.scale = Vec3::ZERO,
            |t: &mut Transform| t.translation = Vec3::splat(f32::MAX),
        ] {
            ao.reset();
            for node in 0..ao.skeleton().nodes.len() {
                let mut t = ao.skeleton().nodes[node].rest;
                degenerate(&mut t);
                ao.set_local(node, t);
            }
            assert!(ao.weights().iter().all(|w| w.is_finite()), "{method}");
            let values = ao.evaluate();
            assert!(
                values.iter().all(|v| (0.0..=1.0).contains(v)),
                "{method}: {:?}",
                &values[..4]
            );
        }
    }
}

/// Blended animations give quaternions a little off unit length; the
/// runtime poses by the rotation they stand for, not the skew a scaled
/// quaternion's matrix would add to vertex-clustered's handles.
#[test]
fn a_rotation_off_unit_length_poses_as_the_unit_one() {
    let (asset, _, _) = bake(
        "RiggedFigure/RiggedFigure.glb",
        Method::VertexClustered,
        false,
    );
    let Asset::Vertex(mut ao) = Asset::from_bytes(&asset).unwrap() else {
        panic!("a vertex asset");
    };
    let node = ao.skeleton().nodes.len() / 2;
    let rest = ao.skeleton().nodes[node].rest;
    let turned = Quat::from_rotation_x(0.6) * rest.rotation;
    let mut at = |scale: f32| {
        ao.reset();
        let mut t = rest;
        t.rotation = turned * scale;
        assert!(ao.set_local(node, t));
        ao.evaluate()
    };
    let unit = at(1.0);
    for scale in [0.5, 0.98, 1.02, 2.0] {
        let worst = at(scale)
            .iter()
            .zip(&unit)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-5, "×{scale}: {worst}");
    }
}
