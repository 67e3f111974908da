//! `aobake bake --tracer gpu`: the wgpu compute tracer in a whole bake, on
//! whatever adapter has compute (lavapipe or llvmpipe without a GPU).

use aobake_e2e::character;

use crate::util::{QUICK, aobake_bake, aobake_bake_on};

fn report(dir: &std::path::Path, name: &str) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join(format!("{name}.json"))).unwrap()).unwrap()
}

#[test]
fn a_bake_traced_on_the_gpu_casts_the_cpus_rays_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let fox = character("Fox");
    let mut args: Vec<&str> = QUICK.to_vec();
    args.extend(["--poses", "24"]);
    let cpu = aobake_bake(dir.path(), &fox, &args, "cpu");
    let (gpu, stderr) = aobake_bake_on(dir.path(), &fox, &args, "gpu", "gpu");
    // "tracer: gpu: ADAPTER (BACKEND, DRIVER)"
    let adapter = stderr
        .lines()
        .find_map(|l| l.strip_prefix("tracer: gpu: "))
        .unwrap_or_else(|| panic!("no GPU tracer line: {stderr}"));
    // "GPU tracer: N submissions, …": the GPU traced, not the CPU behind it.
    let submissions: u64 = stderr
        .lines()
        .find_map(|l| l.strip_prefix("GPU tracer: "))
        .and_then(|l| l.split(' ').next()?.parse().ok())
        .unwrap_or_else(|| panic!("no GPU tracer summary: {stderr}"));
    assert!(submissions > 0, "{stderr}");
    let (cpu_report, gpu_report) = (report(dir.path(), "cpu"), report(dir.path(), "gpu"));
    // The report says which tracing ran on a GPU: all of it, or none.
    let timings = |r: &serde_json::Value, k: &str| r["timings"][k].as_f64().unwrap();
    assert_eq!(timings(&cpu_report, "gpu_trace_s"), 0.0);
    let traced = timings(&gpu_report, "reference_trace_s") + timings(&gpu_report, "test_trace_s");
    assert!(
        (timings(&gpu_report, "gpu_trace_s") - traced).abs() < 1e-9 && traced > 0.0,
        "{}",
        gpu_report["timings"]
    );
    // The same rays through the same arithmetic: on Mesa's software
    // adapters (what CI has) this bake's very asset (a bake with poses
    // that pass parts through each other can differ at a float tie; see
    // worker's extreme_poses_of_a_bake_agree_with_the_cpu_but_at_ties); a
    // hardware GPU may differ where a ray grazes an edge, so there the
    // model's quality must agree.
    let psnr = |r: &serde_json::Value| {
        r["evaluation"]["training_clip_frames"]["model"]["mean"]["psnr_db"]
            .as_f64()
            .unwrap_or_else(|| panic!("no training-frame PSNR in {r}"))
    };
    assert!((psnr(&cpu_report) - psnr(&gpu_report)).abs() < 0.05);
    if adapter.contains("llvmpipe") || adapter.contains("lavapipe") {
        assert!(cpu == gpu, "the GPU tracer's asset differs from the CPU's");
    }
}
