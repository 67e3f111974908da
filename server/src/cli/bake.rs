//! `aobake bake`: a whole bake on this machine, stage by stage as the
//! service's jobs run it (per-vertex: reference AO → fit → held-out AO →
//! evaluate; cubemap: six faces → encode → evaluate), writing the asset,
//! the JSON report and its plot.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use aobake_core::{
    Limits,
    bake::{
        Bake, BakeInputs, Baked, GraphOptions, JobEvent, JobOutput, JobSpec, Renderer, run_graph,
    },
    bake::{BakeReport, cubemap::CubemapReport, grid::GridReport, vertex::Report},
    method::vertex::Rows,
};

use super::common::TracerChoice;
use super::params::BakeRequestArgs;
use super::trace::{progress_bar, with_threads};

/// Arguments of `aobake bake`.
#[derive(Debug, clap::Args)]
#[command(
    after_help = "Unset parameters keep the method's defaults; `aobake params --method M` prints them all, and `--param KEY=VALUE` sets any of them."
)]
pub(super) struct Args {
    #[command(flatten)]
    request: BakeRequestArgs,
    /// Worker threads for tracing. Default: one per core.
    #[arg(long)]
    threads: Option<usize>,
    /// Who casts the rays: `cpu`, `gpu` (the wgpu compute tracer on any
    /// adapter with compute, software ones too), or `auto` (a hardware GPU
    /// when there is one, else the CPU). Both cast the same rays: values
    /// differ only where a ray grazes an edge (float ties).
    #[arg(long, value_enum, default_value = "auto")]
    tracer: TracerChoice,
    /// The asset to write (aobake asset format v1, docs/asset-format.md).
    #[arg(long)]
    out: PathBuf,
    /// The JSON report to write: held-out errors of the model and the
    /// static-average baseline, sizes, timings. Default: beside the
    /// asset, its name with `.report.json` (`fox.aob` → `fox.report.json`).
    #[arg(long)]
    report: Option<PathBuf>,
    /// The report's plot (PNG): PSNR per frame, a cubemap's time ×
    /// distance charts, or slices of every part's grid. Default: the
    /// report's path with `.png`.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Also render the previews with wgpu (a GPU, else a software
    /// adapter) into this folder, as the service's workers do: stills of
    /// truth, model, GTAO and error, the clip's animation, and for texel
    /// bakes stills of each clip an unseen-clip fold left out, drawn with
    /// the model refitted without it; with `previews.json` (how each was
    /// made and judged) and `pixels.json` (every still judged per pixel,
    /// pooled per clip), whose table is printed.
    #[arg(long, value_name = "DIR")]
    previews: Option<PathBuf>,
}

impl Args {
    /// `--report`, or beside the asset: its name with `.report.json`.
    fn report_path(&self) -> PathBuf {
        self.report.clone().unwrap_or_else(|| {
            let stem = self
                .out
                .file_stem()
                .map_or_else(|| "aobake".into(), |s| s.to_string_lossy().into_owned());
            self.out.with_file_name(format!("{stem}.report.json"))
        })
    }
}

/// Reads the character and clip files (with the side files a `.gltf`
/// names) and imports them as the service would the same uploads.
pub(super) fn load_inputs(
    file: &Path,
    clip_files: &[PathBuf],
    limits: &Limits,
) -> anyhow::Result<BakeInputs> {
    let character = super::load::upload(file, limits)?;
    let clips = super::load::clip_uploads(clip_files, limits)?;
    // The error names the input (`character` or `clips[i]`) and carries
    // its import error in its message: one line, not a chain that repeats
    // it.
    let inputs = BakeInputs::load(&character, &clips, limits).map_err(|e| {
        let files: Vec<String> = std::iter::once(file)
            .chain(clip_files.iter().map(PathBuf::as_path))
            .map(|p| p.display().to_string())
            .collect();
        anyhow::anyhow!("cannot import {}: {e}", files.join(", "))
    })?;
    for w in &inputs.warnings {
        eprintln!("warning: {w}");
    }
    Ok(inputs)
}

/// Runs a bake's whole job graph here, with a progress bar over its work;
/// jobs whose spec is in `known` are taken from there.
pub(super) fn run_with_progress(
    bake: &Bake<'_>,
    known: &HashMap<JobSpec, JobOutput>,
    renderer: Option<&mut dyn Renderer>,
) -> anyhow::Result<Vec<JobOutput>> {
    let graph = bake.graph(GraphOptions {
        previews: renderer.is_some(),
        ..GraphOptions::default()
    });
    let bar = progress_bar(graph.total_work(), "baking");
    // Units of the running job already on the bar: the bar moves inside a
    // job (a sample's poses, a fit's steps) and catches up at its end.
    let mut shown = 0u64;
    let outputs = run_graph(bake, &graph, known, renderer, &mut |_, job, event| {
        let work = job.spec.work();
        let done = match event {
            JobEvent::Progress { done, total } => {
                bar.set_message(format!("{} ({done}/{total})", job.spec));
                done.min(work)
            }
            JobEvent::Done(_) => work,
        };
        bar.inc(done.saturating_sub(shown));
        shown = if matches!(event, JobEvent::Done(_)) {
            0
        } else {
            shown.max(done)
        };
    })?;
    bar.finish_and_clear();
    Ok(outputs)
}

fn write(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

/// Fails now, not after the bake, when a file cannot be written where
/// `path` says: its folder must exist and take a new file.
fn check_writable(path: &Path, what: &str) -> anyhow::Result<()> {
    if path.is_dir() {
        bail!("{what} {} is a folder: name a file", path.display());
    }
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !folder.is_dir() {
        bail!(
            "cannot write {what} {}: the folder {} does not exist",
            path.display(),
            folder.display()
        );
    }
    tempfile::NamedTempFile::new_in(folder).with_context(|| {
        format!(
            "cannot write {what} {}: the folder {} does not take new files",
            path.display(),
            folder.display()
        )
    })?;
    Ok(())
}

pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let limits = Limits::default();
    let r = &args.request;
    let params = r.params.params(r.method)?;
    let report = args.report_path();
    if args.out == report {
        bail!("--out and --report must be different files");
    }
    check_writable(&args.out, "--out")?;
    check_writable(&report, "--report")?;
    match &args.plot {
        Some(plot) => check_writable(plot, "--plot")?,
        None => check_writable(&report.with_extension("png"), "the plot")?,
    }
    if let Some(dir) = &args.previews {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot make the previews folder {}", dir.display()))?;
    }
    let inputs = load_inputs(&r.file, &r.clips, &limits)?;
    let bake = Bake::new(&inputs, params)?;
    args.tracer.install(false)?;
    with_threads(args.threads, || run_bake(args, &bake))?
}

/// Writes a bake's previews into `dir`, with `previews.json` and
/// `pixels.json`; prints the per-pixel table.
fn write_previews(dir: &Path, baked: &Baked) -> anyhow::Result<()> {
    for (info, png) in &baked.previews {
        write(&dir.join(&info.name), png)?;
    }
    let infos: Vec<_> = baked.previews.iter().map(|(i, _)| i).collect();
    write(
        &dir.join("previews.json"),
        &serde_json::to_vec_pretty(&infos)?,
    )?;
    eprintln!(
        "wrote {} previews and previews.json into {}",
        baked.previews.len(),
        dir.display()
    );
    if let Some(pixels) = &baked.pixels {
        write(
            &dir.join(aobake_core::bake::screen_space::PIXELS),
            &serde_json::to_vec_pretty(pixels)?,
        )?;
        eprint!("{}", pixels.lines());
    }
    Ok(())
}

fn run_bake(args: &Args, bake: &Bake<'_>) -> anyhow::Result<()> {
    let plan = &bake.plan;
    let character = &bake.inputs.character;
    let clips = &bake.inputs.clips;
    let names =
        |idx: &[usize]| -> Vec<&str> { idx.iter().map(|&i| clips[i].name.as_str()).collect() };
    if let Some(encoding) = aobake_core::method::cubemap_encoding(
        plan.params.method,
        plan.params.cubemap.continuous_layout,
    ) {
        let setup = bake.cubemap_setup()?;
        let o = &setup.options;
        let rays = (o.points() * u64::from(o.rays)) as f64;
        let rays = if rays >= 1e9 {
            format!("{:.2} G rays", rays / 1e9)
        } else {
            format!("{:.1} M rays", rays / 1e6)
        };
        let encoding = super::common::serde_name(&encoding);
        eprintln!(
            "{}: {} vertices, {} triangles; clip {} ({:.2} s); cubemaps ({encoding} encoding) of {}² texels, {} shells, {} time samples, {} rays per point ({rays})",
            args.request.file.display(),
            character.vertex_count(),
            character.triangles.len(),
            setup.clip.name,
            setup.clip.duration,
            o.resolution,
            o.shells,
            o.times,
            o.rays,
        );
    } else {
        eprintln!(
            "{}: {} vertices, {} triangles; {} joint-angle parameters, {} handle coordinates; training clips: {}; test clips: {}",
            args.request.file.display(),
            character.vertex_count(),
            character.triangles.len(),
            plan.joint_angles.len(),
            plan.handles.len(),
            names(&plan.train).join(", "),
            names(&plan.test).join(", "),
        );
    }
    // The renderer is made on the thread that runs the bake.
    let mut renderer = match &args.previews {
        Some(_) => Some(
            aobake_worker::gpu::Gpu::shared()
                .map_err(anyhow::Error::from)
                .and_then(|g| {
                    aobake_worker::gpu::PreviewRenderer::new(g)
                        .context("cannot make the preview renderer")
                })
                .context(
                    "--previews needs a wgpu adapter (a GPU, or Mesa's llvmpipe or lavapipe)",
                )?,
        ),
        None => None,
    };
    let outputs = run_with_progress(
        bake,
        &HashMap::new(),
        renderer.as_mut().map(|r| r as &mut dyn Renderer),
    )?;
    if let Some(summary) = aobake_core::trace::engine::engine().and_then(|e| e.summary()) {
        eprintln!("GPU tracer: {summary}");
    }
    let baked = Baked::from_outputs(&outputs)?;
    write(&args.out, &baked.asset)?;
    let report = args.report_path();
    write(&report, &baked.report_json)?;
    let plot_path = args
        .plot
        .clone()
        .unwrap_or_else(|| report.with_extension("png"));
    write(&plot_path, &baked.plot)?;
    eprintln!(
        "wrote {} ({} bytes), {}, {}",
        args.out.display(),
        baked.asset.len(),
        report.display(),
        plot_path.display()
    );
    eprint!("{}", summary(&baked.report));
    if let Some(dir) = &args.previews {
        write_previews(dir, &baked)?;
    }
    Ok(())
}

/// The lines `aobake bake` and `aobake submit --wait` print about a
/// finished bake.
pub(super) fn summary(report: &BakeReport) -> String {
    match report {
        BakeReport::Vertex(r) => vertex_summary(r),
        BakeReport::Cubemap(r) => cubemap_summary(r),
        BakeReport::Grid(r) => grid_summary(r),
    }
}

/// A grid bake's lines: the parts' grids, then every variant against the
/// ground truth at the parts' vertices and on the ground.
fn grid_summary(report: &GridReport) -> String {
    let e = &report.evaluation;
    let t = &report.timings;
    let mut out = format!(
        "{}: {} parts; {} bytes at run time ({})
| part | vertices | triangles | grid | half extent | V_M | inside cells | bytes (cones / plain) | bake (s) |
|---|---|---|---|---|---|---|---|---|
",
        report.method,
        report.parts.len(),
        report.sizes.model_bytes,
        [
            Some(if report.params.grid.cones {
                "RGBA cells with cones, T_clip"
            } else {
                "a byte a cell"
            }),
            report
                .params
                .grid
                .static_base
                .then_some("the static base's offsets and gains"),
        ]
        .into_iter()
        .flatten()
        .collect::<Vec<_>>()
        .join(", "),
    );
    for p in &report.parts {
        out.push_str(&format!(
            "| {} | {} | {} | {}³ | {:.3} × {:.3} × {:.3} | {:.3} | {} | {} / {} | {:.2} |\n",
            p.name,
            p.vertices,
            p.triangles,
            p.resolution,
            p.half_extent[0],
            p.half_extent[1],
            p.half_extent[2],
            p.boundary_max,
            p.inside_cells,
            p.bytes[0],
            p.bytes[1],
            p.bake_s,
        ));
    }
    out.push_str(&format!(
        "ground truth at {} random clip frames: {} vertices of parts, {} ground points ({} under a contact left out), {} rays each; its own noise RMSE {:.4} (vertices), {:.4} (ground)
| variant | bytes | vertices RMSE | vertices MAE | too dark MSE | too bright MSE | ground RMSE | ground MAE | too dark MSE | too bright MSE |
|---|---|---|---|---|---|---|---|---|---|
",
        e.frames.len(),
        e.vertices,
        e.ground_points,
        e.ground_hidden,
        e.rays_per_point,
        e.noise_rmse_vertices,
        e.noise_rmse_ground,
    ));
    for v in &e.variants {
        let (a, b) = (&v.vertices.mean, &v.ground.mean);
        out.push_str(&format!(
            "| {} | {} | {:.4} | {:.4} | {:.6} | {:.6} | {:.4} | {:.4} | {:.6} | {:.6} |\n",
            v.name,
            v.bytes,
            a.rmse,
            a.mae,
            a.too_dark_mse,
            a.too_bright_mse,
            b.rmse,
            b.mae,
            b.too_dark_mse,
            b.too_bright_mse,
        ));
    }
    out.push_str(&format!(
        "run time: {:.0} ns per receiver on one CPU thread over {} parts\ntimes: slabs {:.1} s, assemble {:.2} s, ground truth {:.1} s, evaluate {:.1} s\n",
        e.lookup_ns_per_receiver,
        report.parts.len(),
        t.reference_trace_s, t.fit_s, t.test_trace_s, t.evaluate_s
    ));
    out
}

/// A cubemap bake's lines: every encoding and reference against the
/// ground truth, in space and on the ground.
fn cubemap_summary(report: &CubemapReport) -> String {
    let e = &report.evaluation;
    let l = &report.layout;
    let t = &report.timings;
    let mut out = format!(
        "{} on clip {}: {}² texels, {} shells, {} time samples; {} bytes of model (texels and any static ground)
ground truth at {} random times: {} points in space ({} inside the mesh left out), {} on the ground ({} under the character left out), {} rays each; its own noise RMSE {:.4}
| variant | bytes | space RMSE | space too dark MSE | space too bright MSE | ground RMSE | ground too dark MSE | ground too bright MSE | fit RMSE |
|---|---|---|---|---|---|---|---|---|
",
        report.method,
        report.clip,
        l.resolution,
        l.spheroid.shells,
        l.times,
        report.sizes.model_bytes,
        e.times.len(),
        e.space_points * e.times.len(),
        e.space_hidden,
        e.ground_points * e.times.len(),
        e.ground_hidden,
        e.rays_per_point,
        e.ground_truth_noise_rmse,
    );
    for v in &e.variants {
        out.push_str(&format!(
            "| {} | {} | {:.4} | {:.6} | {:.6} | {:.4} | {:.6} | {:.6} | {} |\n",
            v.name,
            v.bytes,
            v.space.mean.rmse,
            v.space.mean.too_dark_mse,
            v.space.mean.too_bright_mse,
            v.ground.mean.rmse,
            v.ground.mean.too_dark_mse,
            v.ground.mean.too_bright_mse,
            v.fit.map_or("-".to_owned(), |f| format!("{:.4}", f.rmse)),
        ));
    }
    // What the table's rows are, where their names alone mislead.
    if e.variants.iter().any(|v| v.name == "static ground texture") {
        let others_grounded = e
            .variants
            .iter()
            .any(|v| v.description.contains("on a static ground fitted to it"));
        let others = if others_grounded {
            "the other encodings each on a static ground fitted to it, as their own bakes would be; the uncompressed field and its time average have none"
        } else {
            "the rows after it have none"
        };
        out.push_str(&format!(
            "the first row is the asset: {} with its static ground; {others} (compare their ground columns with \"… without the static ground\"); \"static ground texture\" is the texture alone on the ground and the cubemap elsewhere, so its space columns are the first row's\n",
            report.method
        ));
    }
    out.push_str(&format!(
        "times: faces {:.1} s, encode {:.2} s, ground truth {:.1} s, evaluate {:.1} s\n",
        t.reference_trace_s, t.fit_s, t.test_trace_s, t.evaluate_s
    ));
    out
}

fn vertex_summary(report: &Report) -> String {
    let e = &report.evaluation;
    let n = &report.ground_truth_noise;
    let t = &report.timings;
    let c = &e.training_clip_frames;
    let mut out = String::new();
    if let Some(u) = &e.unseen_clips {
        // The worst left-out clip first: what a studio's next clip risks.
        if let Some(w) = u.worst() {
            out.push_str(&format!(
                "worst unseen clip: {} {:+.2} dB over the static average ({:.2} dB against {:.2} dB)\n",
                w.clip,
                w.errors.psnr_gain_db,
                w.errors.model.mean.psnr_db,
                w.errors.baseline.mean.psnr_db,
            ));
        }
        out.push_str(&format!(
            "unseen clips (leave one clip out, {} folds, worst first): {} PSNR {:.2} dB; static average of the other clips' frames {:.2} dB ({:+.2} dB, worst fold {:+.2} dB)\n",
            u.folds.len(),
            report.method,
            u.model_psnr_db,
            u.baseline_psnr_db,
            u.mean_psnr_gain_db,
            u.min_psnr_gain_db,
        ));
        for f in u.worst_first() {
            out.push_str(&format!(
                "  {}: {:.2} dB against {:.2} dB ({:+.2} dB) over {} frames{}\n",
                f.clip,
                f.errors.model.mean.psnr_db,
                f.errors.baseline.mean.psnr_db,
                f.errors.psnr_gain_db,
                f.errors.model.frames,
                f.rows
                    .map(|r| format!("; fitted to {}", rows_name(r)))
                    .unwrap_or_default()
                    + &f.basis
                        .map(|r| format!("; basis of {r} row{}", if r == 1 { "" } else { "s" }))
                        .unwrap_or_default(),
            ));
        }
    }
    out.push_str(&format!(
        "frames of the training clips, fresh rays ({}): {} PSNR {:.2} dB, MAE {:.4}; static average of training clip frames {:.2} dB, MAE {:.4} ({:+.2} dB, MAE ×{:.2})
ground truth's own noise ({} poses traced twice): RMSE {:.4}, MAE {:.4} (PSNR {:.2} dB): model errors near it are noise
held-out random poses ({}): {:.2} dB against {:.2} dB for the static average; times: reference trace {:.1} s, held-out trace {:.1} s, fit {:.2} s
",
        c.model.frames,
        report.method,
        c.model.mean.psnr_db,
        c.model.mean.mae,
        c.baseline.mean.psnr_db,
        c.baseline.mean.mae,
        c.psnr_gain_db,
        c.mae_ratio,
        n.frames,
        n.rmse,
        n.mae,
        n.psnr_db,
        e.random_poses.model.frames,
        e.random_poses.model.mean.psnr_db,
        e.random_poses.baseline.mean.psnr_db,
        t.reference_trace_s,
        t.test_trace_s,
        t.fit_s,
    ));
    if let Some(a) = &report.texel {
        out.push_str(&format!(
            "atlas: {} × {} texels, {} charts, {} texels show the surface ({:.0}% of the page lies inside its triangles); {} ({:.1} MB as R16Float): per pixel {} and multiply-add{} (texel errors above are per texel; the previews judge per pixel: `--previews DIR`)\n",
            a.width,
            a.height,
            a.charts,
            a.texels,
            100.0 * a.utilisation,
            if a.textures == 1 {
                "1 basis texture".to_owned()
            } else {
                format!("{} basis textures", a.textures)
            },
            a.texture_bytes as f64 / 1e6,
            if a.textures == 1 {
                "1 texture fetch".to_owned()
            } else {
                format!("{} texture fetches", a.textures)
            },
            if a.textures == 1 { "" } else { "s" }
        ));
    }
    if e.undrawn_vertex_frames > 0 {
        out.push_str(&format!(
            "{} vertex-frames of the held-out poses are left out of every error: those vertices draw nothing in that pose (every triangle of theirs has zero area, such as a part scaled to zero)\n",
            e.undrawn_vertex_frames
        ));
    }
    if let Some(c) = report.fit.reference() {
        out.push_str(&format!(
            "reference rows: {} (cross-validation over clips, mean PSNR on left-out clips: {})\n",
            rows_name(c.rows),
            c.scores
                .iter()
                .map(|(rows, db)| format!("{} {db:.2} dB", rows_name(*rows)))
                .collect::<Vec<_>>()
                .join(", "),
        ));
    }
    if let (Some(b), Some(c)) = (report.fit.basis(), report.fit.basis_cv())
        && let (Some(chosen), Some(best)) = (c.chosen(), c.best())
    {
        out.push_str(&format!(
            "eigen-AO basis: {} ({:.1} multiply-adds a {}), the cheapest of {} candidates within {} dB of the best on left-out clips (cross-validation over clips: {:.2} dB; the best, {}, {:.2} dB)\n",
            basis_name(b.rank, b.threshold),
            b.multiply_adds,
            match report.method.family() {
                aobake_core::method::Family::Texel => "texel",
                _ => "vertex",
            },
            c.candidates.len(),
            c.tolerance_db,
            chosen.psnr_db,
            basis_name(best.rank, best.threshold),
            best.psnr_db,
        ));
    }
    out
}

/// "12 rows" or "12 rows, entries under 1/1024 dropped".
fn basis_name(rank: usize, threshold: f32) -> String {
    if threshold > 0.0 {
        format!(
            "{rank} rows, entries under 1/{} dropped",
            (1.0 / threshold).round()
        )
    } else {
        format!("{rank} row{}", if rank == 1 { "" } else { "s" })
    }
}

fn rows_name(rows: Rows) -> &'static str {
    match rows {
        Rows::Mixed => "random poses and clip frames",
        Rows::Perturbed => "clip frames and perturbed frames",
        Rows::All => "all three",
    }
}
