//! `aobake bake --tracer gpu`: the wgpu compute tracer in a whole bake, on
//! whatever adapter has compute (lavapipe or llvmpipe without a GPU).

use aobake_e2e::{binary, character};

use crate::util::{QUICK, aobake_bake};

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
    let out = std::process::Command::new(binary())
        .arg("bake")
        .arg(&fox)
        .args(&args)
        .args(["--tracer", "gpu", "--out"])
        .arg(dir.path().join("gpu.aob"))
        .arg("--report")
        .arg(dir.path().join("gpu.json"))
        .env("RAYON_NUM_THREADS", "2")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let gpu = std::fs::read(dir.path().join("gpu.aob")).unwrap();
    // "tracer: gpu: ADAPTER (BACKEND, DRIVER)"
    let adapter = stderr
        .lines()
        .find_map(|l| l.strip_prefix("tracer: gpu: "))
        .unwrap_or_else(|| panic!("no GPU tracer line: {stderr}"));
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
    // adapters (what CI has) the very same asset; a hardware GPU may differ
    // where a ray grazes an edge, so there the model's quality must agree.
    if adapter.contains("llvmpipe") || adapter.contains("lavapipe") {
        assert!(cpu == gpu, "the GPU tracer's asset differs from the CPU's");
    } else {
        let psnr = |r: &serde_json::Value| r["evaluation"]["model"]["psnr_db"].as_f64().unwrap();
        assert!((psnr(&cpu_report) - psnr(&gpu_report)).abs() < 0.05);
    }
}
