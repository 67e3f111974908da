//! The preview renderer on this machine's adapter (llvmpipe or lavapipe
//! without a GPU): small offscreen renders read back and compared with
//! golden PNGs, and the properties a person relies on when looking at a
//! preview (the model's AO comes from the GPU; the error panel is neutral
//! where the model is right and red where it is too dark).
//!
//! Goldens live in `worker/tests/golden/`; `AOBAKE_BLESS=1` rewrites them
//! (look at them before committing).

use aobake_core::{
    Limits,
    bake::preview::{Ground, Subject},
    bake::screen_space::{Gtao, ScreenSpaceInfo, Surface},
    bake::{BakeParams, Camera, Panel, Plan, RenderFrame, RenderScene, Renderer},
    image::{HEAT_MAP, Image},
    method::Method,
    method::texel::atlas::{AtlasOptions, TexelAtlas},
    method::vertex::Model,
    trace::{AoBlock, SceneOptions, no_progress, trace_poses},
};
use aobake_worker::gpu::{Gpu, PreviewRenderer};
use glam::Vec3;

const SIZE: u32 = 128;

/// Per-channel difference allowed at a pixel, and the share of pixels that
/// may exceed it by up to [`EDGE_TOLERANCE`]. Adapters differ in the last
/// bit of shading (fused multiply-adds, sRGB encoding tables) and in the
/// coverage of multisampled edge pixels (sample positions and rasterisation
/// rules are not the same on GL and Vulkan); a wrong camera, light, AO or
/// colour ramp moves whole regions far past both.
const TOLERANCE: u8 = 6;
const EDGE_SHARE: f64 = 0.03;
const EDGE_TOLERANCE: u8 = 96;

/// The deterministic mode: the software rasteriser the goldens were made
/// on, even on a machine with a GPU.
fn renderer() -> PreviewRenderer<'static> {
    static GPU: std::sync::OnceLock<Gpu> = std::sync::OnceLock::new();
    let gpu = GPU
        .get_or_init(|| Gpu::software().expect("a software wgpu adapter (llvmpipe or lavapipe)"));
    eprintln!("adapter: {} ({:?})", gpu.label(), gpu.info.device_type);
    assert_eq!(gpu.info.device_type, wgpu_types_cpu(), "a software adapter");
    PreviewRenderer::new(gpu).unwrap()
}

fn wgpu_types_cpu() -> aobake_worker::gpu::DeviceType {
    aobake_worker::gpu::DeviceType::Cpu
}

/// RiggedFigure at the middle of its clip, a vertex-linear model fitted to
/// a few poses: the scene of the goldens.
struct Fixture {
    character: aobake_core::Character,
    model: Model,
    frame: RenderFrame,
    camera: Camera,
    ground: Ground,
}

fn fixture() -> Fixture {
    let imported = super::bundled("RiggedFigure");
    let c = imported.character;
    let mut params = BakeParams::new(Method::VertexLinear);
    params.poses = 48;
    params.samples = 64;
    let plan = Plan::new(&c, &imported.clips, params.clone()).unwrap();
    let poses = plan.reference_poses();
    let surface = params.surface();
    let ao = trace_poses(&c, &poses, &SceneOptions::default(), &surface, &no_progress).unwrap();
    let (model, _) = plan.fit(&poses, &ao, &plan.reference_sources()).unwrap();
    let clip = &imported.clips[0];
    let subject = Subject::new(
        &c,
        aobake_core::bake::PreviewModel::Vertex(&model),
        params.held_out_surface(),
    );
    let camera = subject.camera(Some(clip));
    let ground = camera.ground();
    let frame = subject
        .frames(Some(clip), &[0.5 * clip.duration], &ground)
        .unwrap()
        .remove(0);
    // The figure casts occlusion on the ground under it.
    assert!(frame.ground_ao.iter().any(|&a| a > 0.2), "contact shadow");
    Fixture {
        character: c,
        model,
        frame,
        camera,
        ground,
    }
}

fn scene<'a>(f: &'a Fixture, model: &'a Model) -> RenderScene<'a> {
    RenderScene {
        triangles: &f.character.triangles,
        model: aobake_core::bake::PreviewModel::Vertex(model),
        camera: f.camera,
        ground: &f.ground,
        size: (SIZE, SIZE),
        heat_map: HEAT_MAP,
        gtao: Gtao::for_camera(&f.camera, f32::INFINITY),
    }
}

fn golden_path(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(name)
}

fn read_png(path: &std::path::Path) -> Image {
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    ));
    let mut reader = decoder.read_info().unwrap();
    let mut rgba = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut rgba).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba);
    Image {
        width: info.width,
        height: info.height,
        rgba,
    }
}

/// Compares with the golden (or writes it when blessing), and writes the
/// render beside the test's artifacts for a person to look at.
fn check_golden(name: &str, image: &Image) {
    let artifacts = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("previews");
    std::fs::create_dir_all(&artifacts).unwrap();
    let png = aobake_core::image::encode_image(image).unwrap();
    std::fs::write(artifacts.join(name), &png).unwrap();
    let path = golden_path(name);
    if std::env::var_os("AOBAKE_BLESS").is_some() {
        std::fs::write(&path, &png).unwrap();
        return;
    }
    let golden = read_png(&path);
    assert_eq!((golden.width, golden.height), (image.width, image.height));
    let mut over = 0usize;
    let mut worst = 0u8;
    for (a, b) in golden.rgba.iter().zip(&image.rgba) {
        let d = a.abs_diff(*b);
        worst = worst.max(d);
        if d > TOLERANCE {
            over += 1;
        }
    }
    let share = over as f64 / image.rgba.len() as f64;
    eprintln!("{name}: {over} channels over ±{TOLERANCE} ({share:.4}), worst {worst}");
    assert!(
        share <= EDGE_SHARE && worst <= EDGE_TOLERANCE,
        "{name} differs from its golden: {share:.4} of channels over ±{TOLERANCE}, worst {worst} (render in {})",
        artifacts.display()
    );
}

fn pixel(image: &Image, x: u32, y: u32) -> [u8; 4] {
    let i = (4 * (y * image.width + x)) as usize;
    image.rgba[i..i + 4].try_into().unwrap()
}

#[test]
fn panels_match_their_goldens() {
    let f = fixture();
    let mut r = renderer();
    let panels = [Panel::Truth, Panel::Model, Panel::Error, Panel::ScreenSpace];
    let images = r
        .render(
            &scene(&f, &f.model),
            std::slice::from_ref(&f.frame),
            &panels,
        )
        .unwrap();
    assert_eq!(images.len(), 4);
    for (image, name) in
        images
            .iter()
            .zip(["truth.png", "model.png", "error.png", "screen-space.png"])
    {
        check_golden(name, image);
    }
    // Rendering again gives the same bytes: nothing jitters.
    let again = r
        .render(
            &scene(&f, &f.model),
            std::slice::from_ref(&f.frame),
            &panels,
        )
        .unwrap();
    assert_eq!(again, images, "a second render differs");
}

/// The screen-space baseline's buffers: the G-buffer holds each pixel's
/// surface where the panels draw it, and GTAO (gtao.wgsl) is open on the
/// open ground, dark in the figure's contact shadow, and absent off the
/// surfaces.
#[test]
fn gtao_is_open_on_open_ground_and_dark_where_the_figure_meets_it() {
    let f = fixture();
    let mut r = renderer();
    let scene = scene(&f, &f.model);
    let screen = r
        .screen_space(&scene, std::slice::from_ref(&f.frame))
        .unwrap()
        .remove(0);
    let pixels = (SIZE * SIZE) as usize;
    assert_eq!((screen.width, screen.height), (SIZE, SIZE));
    assert_eq!(screen.gtao.len(), pixels);
    let surfaces = &screen.surfaces;
    let of = |s: Surface| (0..pixels).filter(move |&i| surfaces[i] == s);
    let (character, ground, none) = (
        of(Surface::Character).count(),
        of(Surface::Ground).count(),
        of(Surface::None).count(),
    );
    eprintln!("pixels: {character} character, {ground} ground, {none} background");
    assert!(character > 200 && ground > 2000 && none > 200);
    // Positions: the figure's pixels lie in its posed box, the ground's on
    // the ground plane.
    let (lo, hi) = f
        .frame
        .positions
        .iter()
        .fold((Vec3::MAX, Vec3::MIN), |(lo, hi), &p| {
            (lo.min(p), hi.max(p))
        });
    let slack = 1e-3 * (hi - lo).length();
    for i in of(Surface::Character) {
        let p = screen.positions[i];
        assert!(
            p.cmpge(lo - slack).all() && p.cmple(hi + slack).all(),
            "pixel {i} at {p} is off the figure"
        );
        assert!(
            (-1e-3..=1.001).contains(&screen.truth[i]),
            "truth {} at pixel {i}",
            screen.truth[i]
        );
    }
    for i in of(Surface::Ground) {
        assert!((screen.positions[i].y - f.camera.ground_y).abs() <= slack);
    }
    for i in of(Surface::None) {
        assert!(screen.gtao[i] < 0.0, "no occlusion off the surfaces");
    }
    // The ground: open far from the figure (an open plane's visibility is
    // exactly 1), dark near its feet.
    let radius = f.camera.scene_radius();
    let distance = |i: usize| {
        let p = screen.positions[i];
        (p.x - f.camera.target.x).hypot(p.z - f.camera.target.z)
    };
    let far: Vec<f32> = of(Surface::Ground)
        .filter(|&i| distance(i) > 1.5 * radius)
        .map(|i| screen.gtao[i])
        .collect();
    assert!(!far.is_empty());
    let worst = far.iter().copied().fold(0.0f32, f32::max);
    assert!(worst < 0.02, "open ground gets {worst}");
    let near = of(Surface::Ground)
        .filter(|&i| distance(i) < 0.3 * radius)
        .map(|i| screen.gtao[i])
        .fold(0.0f32, f32::max);
    assert!(near > 0.2, "the contact shadow gets {near}");
    // Deterministic: the same buffers again.
    let again = r
        .screen_space(&scene, std::slice::from_ref(&f.frame))
        .unwrap()
        .remove(0);
    assert_eq!(again.gtao, screen.gtao);
    assert_eq!(again.positions, screen.positions);
}

/// The per-pixel comparison: the model and GTAO against AO ray-traced at
/// the pixels' own points; a model that is wrong everywhere scores worse
/// than the baked one, and the per-vertex truth on the ground (the same
/// quantity at the ground's vertices) is close to it.
#[test]
fn the_screen_space_comparison_judges_the_model_and_gtao_per_pixel() {
    let f = fixture();
    let mut r = renderer();
    let params = {
        let mut p = BakeParams::new(Method::VertexLinear);
        p.samples = 64;
        p
    };
    let measure_with = |r: &mut PreviewRenderer<'_>,
                        model: &Model,
                        frame: &RenderFrame,
                        atlas: Option<&TexelAtlas>| {
        let scene = scene(&f, model);
        let screen = r
            .screen_space(&scene, std::slice::from_ref(frame))
            .unwrap()
            .remove(0);
        ScreenSpaceInfo::measure(
            &screen,
            frame,
            &f.character.triangles,
            &scene.model,
            &f.camera,
            scene.gtao,
            &params.held_out_surface(),
            atlas.map(|atlas| aobake_core::bake::screen_space::TexelJudge { atlas, models: &[] }),
        )
        .unwrap()
    };
    let measure = |r: &mut PreviewRenderer<'_>, model: &Model, frame: &RenderFrame| {
        measure_with(r, model, frame, None)
    };
    let baked = measure(&mut r, &f.model, &f.frame);
    assert!(baked.atlas.is_none() && baked.character.as_ref().unwrap().texel_truth.is_none());
    eprint!("{}", baked.summary());
    let character = baked.character.unwrap();
    let ground = baked.ground.unwrap();
    let model = character
        .model
        .expect("a vertex model shades the character");
    assert!(
        ground.model.is_none(),
        "a vertex model does not shade the ground"
    );
    assert!(model.rmse < 0.2 && character.gtao.rmse < 0.3);
    assert!(ground.per_vertex_truth.rmse < 0.05);
    assert!(ground.gtao.rmse > ground.per_vertex_truth.rmse);
    assert!(baked.gtao_ms > 0.0 && baked.fetches_per_pixel == 2 * Gtao::SLICES * Gtao::STEPS);
    // Fully occluded everywhere: far worse per pixel.
    let vertices = f.character.vertex_count();
    let closed = Model::StaticAverage(aobake_core::method::vertex::fit_static_average(&AoBlock {
        vertices,
        values: vec![1.0; vertices],
    }));
    let mut frame = f.frame.clone();
    frame.weights = vec![1.0];
    let wrong = measure(&mut r, &closed, &frame);
    let wrong_model = wrong.character.as_ref().unwrap().model.unwrap();
    assert!(
        wrong_model.rmse > model.rmse + 0.3,
        "closed {} against baked {}",
        wrong_model.rmse,
        model.rmse
    );
    // GTAO does not depend on the model.
    assert_eq!(wrong.character.as_ref().unwrap().gtao, character.gtao);
    // With an atlas, the texel floor: the traced texels looked up where
    // the eye meets the figure, closer to per-pixel AO than the per-vertex
    // truth on its flat, low-poly limbs (the figure's 370 vertices sit on
    // creases that interpolation spreads over open faces).
    let c = &f.character;
    let atlas = TexelAtlas::generate(&c.positions, &c.triangles, &AtlasOptions::default()).unwrap();
    let texel = measure_with(&mut r, &f.model, &f.frame, Some(&atlas));
    eprint!("{}", texel.summary());
    let info = texel.atlas.as_ref().unwrap();
    assert_eq!(info.texels, atlas.texels.len());
    let on_character = texel.character.as_ref().unwrap();
    let floor = on_character.texel_truth.unwrap();
    assert_eq!(on_character.per_vertex_truth, character.per_vertex_truth);
    assert!(
        floor.rmse < 0.75 * character.per_vertex_truth.rmse,
        "texel floor {} against the per-vertex truth's {}",
        floor.rmse,
        character.per_vertex_truth.rmse
    );
    assert!(texel.summary().contains("texel truth"));
}

#[test]
fn the_model_panel_shades_with_the_gpu_evaluation_of_the_model() {
    let f = fixture();
    let mut r = renderer();
    // A model that is fully open everywhere and one fully occluded: the
    // model panel follows the model, not the ground truth.
    let constant = |value: f32| {
        let vertices = f.character.vertex_count();
        Model::StaticAverage(aobake_core::method::vertex::fit_static_average(&AoBlock {
            vertices,
            values: vec![value; vertices],
        }))
    };
    let (open, closed) = (constant(0.0), constant(1.0));
    let mut frame = f.frame.clone();
    frame.weights = vec![1.0];
    let render = |r: &mut PreviewRenderer<'_>, m: &Model, panel| {
        r.render(&scene(&f, m), std::slice::from_ref(&frame), &[panel])
            .unwrap()
            .remove(0)
    };
    let bright = render(&mut r, &open, Panel::Model);
    let dark = render(&mut r, &closed, Panel::Model);
    let truth = render(&mut r, &open, Panel::Truth);
    let centre = (SIZE / 2, SIZE / 2);
    let lum = |i: &Image| pixel(i, centre.0, centre.1)[1];
    assert!(
        lum(&bright) > lum(&dark) + 40,
        "open {} vs closed {}",
        lum(&bright),
        lum(&dark)
    );
    assert_eq!(
        truth,
        render(&mut r, &closed, Panel::Truth),
        "the truth panel ignores the model"
    );
    // Error: the closed model is far too dark (red), the open one too
    // bright (blue) wherever the truth has occlusion.
    let red = render(&mut r, &closed, Panel::Error);
    let [rr, _, rb, _] = pixel(&red, centre.0, centre.1);
    assert!(rr > rb + 60, "too dark is red: {rr} vs {rb}");
    let bg = pixel(&red, 0, 0);
    assert!(bg[2] > bg[0], "the corner is background");
}

/// Mean brightness (0..255) of an image's RGB.
fn mean_brightness(image: &Image) -> f64 {
    let sum: u64 = image
        .rgba
        .chunks_exact(4)
        .map(|p| u64::from(p[0]) + u64::from(p[1]) + u64::from(p[2]))
        .sum();
    sum as f64 / (3 * image.rgba.len() / 4) as f64
}

/// The truth and model panels of one frame of `clip` at `time`, the model
/// given as `subject.model`.
fn truth_and_model(
    subject: &Subject<'_>,
    clip: &aobake_core::Clip,
    time: f32,
    r: &mut PreviewRenderer<'_>,
) -> Vec<Image> {
    let camera = subject.camera(Some(clip));
    let ground = camera.ground();
    let frames = subject.frames(Some(clip), &[time], &ground).unwrap();
    let scene = RenderScene {
        triangles: &subject.character.triangles,
        model: subject.model,
        camera,
        ground: &ground,
        size: (SIZE, SIZE),
        heat_map: HEAT_MAP,
        gtao: Gtao::for_camera(&camera, f32::INFINITY),
    };
    r.render(&scene, &frames, &[Panel::Truth, Panel::Model])
        .unwrap()
}

/// Mean brightness of (truth, baked model, all-open model) from two
/// renders of the same frame, after checking that their truth panels are
/// the same ray-traced image.
fn brightness(baked: &[Image], open: &[Image]) -> (f64, f64, f64) {
    assert_eq!(baked[0], open[0], "the same ray-traced truth");
    (
        mean_brightness(&baked[0]),
        mean_brightness(&baked[1]),
        mean_brightness(&open[1]),
    )
}

/// A bake's previews, made by its graph (the truth traced by its
/// `preview-truth` jobs, in batches, beside the other tracing), are byte
/// for byte the previews traced and rendered in one go from its asset, as
/// `aobake preview` makes them; and the `preview` job needs those jobs.
fn previews_match_one_go(
    bake: &aobake_core::bake::Bake<'_>,
    baked: &aobake_core::bake::Baked,
    r: &mut PreviewRenderer<'_>,
) {
    use aobake_core::{
        asset::Container,
        bake::{BakedAsset, GraphOptions, JobSpec},
    };
    let graph = bake.graph(GraphOptions::default());
    let truth: Vec<usize> = (0..graph.jobs.len())
        .filter(|&i| matches!(graph.jobs[i].spec, JobSpec::PreviewTruth { .. }))
        .collect();
    let frames = bake.preview_frames().unwrap();
    let mut next = 0;
    for &t in &truth {
        let JobSpec::PreviewTruth { first, count } = graph.jobs[t].spec else {
            unreachable!()
        };
        assert_eq!(first, next, "truth batches cover the frames in order");
        next += count;
    }
    assert_eq!(next, frames.len());
    let preview = graph.jobs.last().unwrap();
    assert_eq!(preview.spec, JobSpec::Preview);
    assert!(truth.iter().all(|t| preview.deps.contains(t)));
    assert!(truth.iter().all(|&t| graph.jobs[t].deps.is_empty()));

    let container = Container::from_bytes(&baked.asset).unwrap();
    let asset = BakedAsset::read(&container, Some(&bake.inputs.character)).unwrap();
    let (model, surface) = asset.preview_model().unwrap();
    let subject = Subject::new(&bake.inputs.character, model, surface);
    let mut one_go = subject
        .stills(frames.clip, &frames.stills, None, r)
        .unwrap();
    if let Some(c) = frames.clip {
        one_go.push(subject.animation(c, None, r).unwrap());
    }
    assert_eq!(one_go.len(), baked.previews.len());
    for (a, (info, png)) in one_go.iter().zip(&baked.previews) {
        assert_eq!(a.info.name, info.name);
        assert_eq!(a.info.times, info.times);
        assert!(a.png == *png, "{} differs", info.name);
    }
}

/// A test file's inputs (`tests/data/…`), imported for a bake.
/// A texel bake with unseen-clip folds judges each fold per pixel on
/// stills of the clip it left out, drawn with the fold's model (which
/// never saw the clip) beside the fold's static average; the preview job
/// pools every still per clip into its per-pixel summary.
#[test]
fn a_texel_bake_judges_its_unseen_folds_per_pixel() {
    use aobake_core::bake::{
        Bake, BakeReport, bake_in_process, screen_space::PixelSummary, texel::UNSEEN_KIND,
    };
    let inputs = test_inputs("characters/Fox/Fox.glb");
    let mut p = BakeParams::new(Method::TexelLinear);
    p.poses = 48;
    p.samples = 8;
    p.eval_poses = 2;
    p.eval_fps = 4.0;
    p.eval_folds = 2;
    p.texel.atlas = 64;
    let bake = Bake::new(&inputs, p).unwrap();
    let mut r = renderer();
    let baked = bake_in_process(&bake, Some(&mut r)).unwrap();
    let BakeReport::Vertex(report) = &baked.report else {
        panic!("a texel bake's report is the vertex family's");
    };
    let folds = &report.evaluation.unseen_clips.as_ref().unwrap().folds;
    assert_eq!(folds.len(), 2);
    let unseen: Vec<_> = baked
        .previews
        .iter()
        .map(|(info, _)| info)
        .filter(|i| i.kind == UNSEEN_KIND)
        .collect();
    // Two stills a fold, at the fold's own times, named by fold.
    assert_eq!(unseen.len(), 4);
    for (fold, f) in folds.iter().enumerate() {
        assert_eq!(f.stills.len(), 2, "{f:?}");
        for (i, &t) in f.stills.iter().enumerate() {
            let info = unseen[2 * fold + i];
            assert_eq!(info.name, format!("unseen-{fold}-{i}.png"));
            assert_eq!(info.clip.as_deref(), Some(f.clip.as_str()));
            assert_eq!(info.times, [t]);
            let e = info
                .screen_space
                .as_ref()
                .unwrap()
                .character
                .as_ref()
                .unwrap();
            assert!(e.model.is_some() && e.texel_truth.is_some());
            assert_eq!(
                e.texel_models.len(),
                1,
                "the fold's static average beside it"
            );
        }
    }
    // The fold's model is not the bake's: the bake's own model, which
    // trained on the clip, drawn at the same still scores otherwise.
    let (info, _) = baked
        .previews
        .iter()
        .find(|(i, _)| i.name == "unseen-0-0.png")
        .unwrap();
    let container = aobake_core::asset::Container::from_bytes(&baked.asset).unwrap();
    let asset = aobake_core::bake::BakedAsset::read(&container, Some(&inputs.character)).unwrap();
    let (model, surface) = asset.preview_model().unwrap();
    let subject = Subject::new(&inputs.character, model, surface);
    let clip = inputs
        .clips
        .iter()
        .find(|c| Some(&c.name) == info.clip.as_ref())
        .unwrap();
    let own = subject
        .stills(Some(clip), &info.times, None, &mut r)
        .unwrap();
    let score = |s: &aobake_core::bake::screen_space::ScreenSpaceInfo| {
        s.character.as_ref().unwrap().model.unwrap().rmse
    };
    let (folded, trained) = (
        score(info.screen_space.as_ref().unwrap()),
        score(own[0].info.screen_space.as_ref().unwrap()),
    );
    assert!(
        (folded - trained).abs() > 1e-4,
        "the fold's model scores {folded}, the bake's {trained}"
    );

    // The summary pools the stills per clip, as the preview job wrote it.
    let summary = PixelSummary::of(baked.previews.iter().map(|(i, _)| i), |clip| {
        report.character.train_clips.iter().any(|c| c == clip)
    })
    .unwrap();
    eprint!("{}", summary.lines());
    assert_eq!(summary.unseen.len(), 2);
    assert!(summary.stills.iter().all(|e| e.trained && e.stills == 3));
    for (e, f) in summary.unseen.iter().zip(folds) {
        assert_eq!(
            (e.clip.as_str(), e.trained, e.stills),
            (f.clip.as_str(), false, 2)
        );
        let (model, statics) = (e.model, e.static_average.unwrap());
        assert!((e.gain_db.unwrap() - 20.0 * (statics / model).log10()).abs() < 1e-9);
        assert!(e.texel_floor.unwrap() > 0.0 && e.gtao > 0.0);
    }
    let worst = summary
        .unseen
        .iter()
        .map(|e| e.gain_db.unwrap())
        .fold(f64::INFINITY, f64::min);
    assert_eq!(summary.unseen_worst_gain_db, Some(worst));
}

fn test_inputs(path: &str) -> aobake_core::bake::BakeInputs {
    use aobake_core::bake::{BakeInputs, UploadBytes};
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/data")
        .join(path);
    BakeInputs::load(
        &UploadBytes::single(std::fs::read(path).unwrap()),
        &[],
        &Limits::default(),
    )
    .unwrap()
}

#[test]
fn a_vertex_bakes_previews_are_those_of_its_asset() {
    use aobake_core::bake::{Bake, bake_in_process};
    let inputs = test_inputs("characters/RiggedFigure/RiggedFigure.glb");
    let mut p = BakeParams::new(Method::VertexLinear);
    p.poses = 24;
    p.samples = 16;
    p.eval_poses = 4;
    let bake = Bake::new(&inputs, p).unwrap();
    let mut r = renderer();
    let baked = bake_in_process(&bake, Some(&mut r)).unwrap();
    previews_match_one_go(&bake, &baked, &mut r);
}

#[test]
fn a_cubemap_preview_shades_the_ground_with_the_gpu_lookup_and_the_bake_gets_its_previews() {
    use aobake_core::{
        asset::Container,
        bake::{Bake, PreviewModel, bake_in_process},
        method::cubemap::model::CubemapModel,
    };
    let inputs = test_inputs("scenes/SpinningCube/SpinningCube.gltf");
    let mut p = super::gpu::small_cubemap(Method::CubemapContinuous, 16, 4, 32, 32);
    // The previews' ground truth traces this many rays per ground point.
    p.cubemap.eval_rays = 32;
    let bake = Bake::new(&inputs, p.clone()).unwrap();
    let mut r = renderer();
    let baked = bake_in_process(&bake, Some(&mut r)).unwrap();
    let names: Vec<&str> = baked
        .previews
        .iter()
        .map(|(i, _)| i.name.as_str())
        .collect();
    assert_eq!(
        names,
        ["still-0.png", "still-1.png", "still-2.png", "animation.png"]
    );
    assert_eq!(baked.previews[0].0.clip.as_deref(), Some("spin"));
    // A still: four panels, and the screen-space baseline judged beside
    // the cubemap (which shades the ground with Eq. 3.1, so only GTAO is
    // judged there).
    let still = &baked.previews[0].0;
    assert_eq!(still.width, 4 * aobake_core::bake::preview::STILL_PANEL);
    let screen = still.screen_space.as_ref().expect("a still's baseline");
    let ground = screen.ground.as_ref().expect("ground pixels");
    assert!(ground.model.is_none() && ground.pixels > 100);
    assert!(
        ground
            .model_not_judged
            .as_deref()
            .unwrap_or("")
            .contains("Eq. 3.1"),
        "{ground:?}"
    );
    assert!(
        baked.previews[3].0.screen_space.is_none(),
        "not on an animation"
    );
    previews_match_one_go(&bake, &baked, &mut r);
    // The model panel's ground comes from the cubemap: the baked one
    // darkens it around the cube, an all-open one (zero texels, no static
    // ground) does not.
    let (model, _) =
        CubemapModel::from_container(&Container::from_bytes(&baked.asset).unwrap()).unwrap();
    let open = CubemapModel {
        texels: vec![0; model.texels.len()],
        layout: aobake_core::method::cubemap::model::CubemapLayout {
            encoding: aobake_core::method::cubemap::model::Encoding::Discrete,
            ..model.layout
        },
        ground: None,
    };
    let kroon = p.cubemap_truth(&model.layout.spheroid);
    let clip = &inputs.clips[0];
    let render = |m: &CubemapModel, r: &mut PreviewRenderer<'_>| {
        let subject = Subject::new(
            &inputs.character,
            PreviewModel::Cubemap(m, kroon),
            p.held_out_surface(),
        );
        truth_and_model(&subject, clip, 0.5, r)
    };
    let (truth, with, without) = brightness(&render(&model, &mut r), &render(&open, &mut r));
    eprintln!("mean brightness: truth {truth:.2}, cubemap {with:.2}, open {without:.2}");
    assert!(with < without - 0.5, "the cubemap darkens the ground");
    assert!(
        (with - truth).abs() < (without - truth).abs(),
        "and brings it closer to the truth"
    );
}

#[test]
fn a_grid_preview_shades_the_parts_and_the_ground_with_the_gpu_lookup() {
    use aobake_core::{
        asset::Container,
        bake::{Bake, PreviewModel, bake_in_process},
        method::grid::{
            GridOptions,
            model::GridModel,
            parts::{owner_indices, parts},
        },
    };
    let inputs = test_inputs("scenes/RigidRobot/RigidRobot.gltf");
    let mut p = aobake_core::bake::BakeParams::new(Method::Grid);
    p.grid = GridOptions {
        resolution: 16,
        rays: 64,
        eval_frames: 1,
        eval_ground: 16,
        eval_rays: 32,
        average_frames: 1,
        ..GridOptions::default()
    };
    let bake = Bake::new(&inputs, p.clone()).unwrap();
    let mut r = renderer();
    let baked = bake_in_process(&bake, Some(&mut r)).unwrap();
    assert_eq!(baked.previews.len(), 4, "three stills and an animation");
    previews_match_one_go(&bake, &baked, &mut r);
    // The model panel comes from the grids: the baked ones darken the
    // parts and the ground towards the truth, all-open ones (zero cells)
    // do not.
    let (model, _) =
        GridModel::from_container(&Container::from_bytes(&baked.asset).unwrap()).unwrap();
    let mut open = model.clone();
    for part in &mut open.parts {
        part.occlusion.fill(0);
    }
    let c = &inputs.character;
    let owner = owner_indices(&parts(c, p.grid.parts).unwrap(), c.vertex_count());
    let surface = p
        .grid
        .truth(bake.grid_distance(&bake.grid_parts().unwrap()), 99);
    let clip = &inputs.clips[0];
    let render = |m: &GridModel, r: &mut PreviewRenderer<'_>| {
        let subject = Subject::new(c, PreviewModel::Grid(m, &owner), surface);
        truth_and_model(&subject, clip, 0.4, r)
    };
    let (truth, with, without) = brightness(&render(&model, &mut r), &render(&open, &mut r));
    eprintln!("mean brightness: truth {truth:.2}, grids {with:.2}, open {without:.2}");
    assert!(with < without - 0.2, "the grids darken the scene");
    assert!(
        (with - truth).abs() < (without - truth).abs(),
        "and bring it closer to the truth"
    );
}

/// A texel-linear bake's previews: the truth at the atlas's texels traced
/// by its `preview-truth` jobs, the model drawn per pixel from its basis
/// textures (byte for byte what `aobake preview` renders from the asset),
/// judged per pixel; and the shader's textures weighted as the runtime's.
#[test]
fn a_texel_bakes_previews_draw_its_textures_per_pixel() {
    use aobake_core::{
        asset::Container,
        bake::{Bake, BakedAsset, PreviewModel, bake_in_process},
        method::texel::TexelModel,
    };
    use aobake_worker::gpu::TexelAo;
    let inputs = test_inputs("characters/RiggedFigure/RiggedFigure.glb");
    let mut p = BakeParams::new(Method::TexelLinear);
    p.poses = 48;
    p.samples = 16;
    p.eval_poses = 4;
    p.texel.atlas = 128;
    let bake = Bake::new(&inputs, p).unwrap();
    let mut r = renderer();
    let baked = bake_in_process(&bake, Some(&mut r)).unwrap();
    previews_match_one_go(&bake, &baked, &mut r);
    let still = &baked.previews[0].0;
    let screen = still.screen_space.as_ref().unwrap();
    eprint!("{}", screen.summary());
    let on_character = screen.character.as_ref().unwrap();
    let model = on_character
        .model
        .expect("a texel model is judged per pixel");
    let floor = on_character.texel_truth.expect("its texel floor beside it");
    assert_eq!(screen.atlas.as_ref().unwrap().width, 128);
    assert!(
        screen.ground.as_ref().unwrap().model.is_none(),
        "a texel model does not shade the ground"
    );
    // The fitted model sits near the floor of its own atlas, and both are
    // far closer to per-pixel AO than a closed or open surface would be.
    assert!(
        model.rmse < floor.rmse + 0.05 && model.rmse < 0.15,
        "model {} against its floor {}",
        model.rmse,
        floor.rmse
    );

    // The shader's sum over the basis textures is the runtime's: exact at
    // texel centres (the textures hold the asset's f16 coefficients), and
    // the bilinear blend between them.
    let container = Container::from_bytes(&baked.asset).unwrap();
    let (texel, _) = TexelModel::from_container(&container, None).unwrap();
    let c = &inputs.character;
    let clip = &inputs.clips[0];
    let pose = aobake_core::Pose::sample(&c.skeleton, clip, 0.3 * clip.duration);
    let w = texel.model.weights(&c.skeleton, &pose.locals);
    let basis: Vec<Vec<f32>> = texel
        .basis()
        .unwrap()
        .into_iter()
        .map(|l| {
            l.into_iter()
                .map(|v| half::f16::from_f32(v).to_f32())
                .collect()
        })
        .collect();
    let (width, height) = (texel.atlas.width, texel.atlas.height);
    let cpu = |uv: [f32; 2]| -> f32 {
        let sum: f32 = basis
            .iter()
            .zip(&w)
            .map(|(layer, wk)| {
                wk * aobake_core::method::texel::atlas::bilinear(layer, width, height, uv.into())
            })
            .sum();
        sum.clamp(0.0, 1.0)
    };
    let gpu = TexelAo::new(r.gpu(), &texel).unwrap();
    assert_eq!(gpu.layers() as usize, w.len());
    let values = texel.model.evaluate_weights(&w);
    for (offset, tolerance) in [([0.0, 0.0], 1e-5), ([0.3, -0.45], 2e-2)] {
        let drawn = gpu.evaluate(&w, offset).unwrap();
        assert_eq!(drawn.len(), (width * height) as usize);
        let mut worst = 0.0f32;
        for y in 0..height {
            for x in 0..width {
                let uv = [
                    (x as f32 + 0.5 + offset[0]) / width as f32,
                    (y as f32 + 0.5 + offset[1]) / height as f32,
                ];
                worst = worst.max((drawn[(y * width + x) as usize] - cpu(uv)).abs());
            }
        }
        assert!(worst <= tolerance, "offset {offset:?}: {worst}");
    }
    // At the texels themselves, the model's own values (f16 coefficients).
    let centres = gpu.evaluate(&w, [0.0, 0.0]).unwrap();
    for (column, &t) in texel.atlas.texels.iter().enumerate() {
        let d = (centres[t as usize] - values[column]).abs();
        assert!(
            d < 1e-4,
            "texel {t}: {} against {}",
            centres[t as usize],
            values[column]
        );
    }

    // The asset read with its character previews as a texel model, and
    // the pixels the GPU drew from its textures score as the model's
    // values looked up on the CPU where the eye meets the mesh: the
    // G-buffer holds the textures' AO, not a per-vertex one.
    let asset = BakedAsset::read(&container, Some(c)).unwrap();
    let (model, surface) = asset.preview_model().unwrap();
    let PreviewModel::Texel(_, atlas) = model else {
        panic!("a texel asset previews as a texel model");
    };
    let subject = Subject::new(c, model, surface);
    let camera = subject.camera(Some(clip));
    let ground = camera.ground();
    let frame = subject
        .frames(Some(clip), &[0.3 * clip.duration], &ground)
        .unwrap()
        .remove(0);
    let scene = RenderScene {
        triangles: &c.triangles,
        model,
        camera,
        ground: &ground,
        size: (SIZE, SIZE),
        heat_map: HEAT_MAP,
        gtao: Gtao::for_camera(&camera, f32::INFINITY),
    };
    let screen = r
        .screen_space(&scene, std::slice::from_ref(&frame))
        .unwrap()
        .remove(0);
    let values = texel.model.evaluate_weights(&frame.weights);
    let judged = ScreenSpaceInfo::measure(
        &screen,
        &frame,
        &c.triangles,
        &model,
        &camera,
        scene.gtao,
        &surface,
        Some(aobake_core::bake::screen_space::TexelJudge {
            atlas,
            models: std::slice::from_ref(&values),
        }),
    )
    .unwrap();
    let on_character = judged.character.unwrap();
    let (gpu, cpu) = (on_character.model.unwrap(), on_character.texel_models[0]);
    eprintln!(
        "per pixel: GPU-drawn model {:.4}, CPU lookup {:.4}",
        gpu.rmse, cpu.rmse
    );
    assert!(
        (gpu.rmse - cpu.rmse).abs() < 0.005,
        "GPU {} against CPU {}",
        gpu.rmse,
        cpu.rmse
    );
}
