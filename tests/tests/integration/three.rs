//! A glTF export in a stock three.js (npm `three`, pinned in
//! `tests/tools`): the GLTFLoader in a real headless Chromium (WebGL2 on
//! SwiftShader) loads a texel asset's export, takes its occlusionTexture
//! as the material's aoMap on the atlas's UV set, and the AO darkens the
//! render where it should, with no aobake code in the page
//! (`tests/tools/three/occlusion.html`). The renders are written under
//! `target/tmp/dashboard/` for a person to look at.

use std::process::{Child, Command, Stdio};
use std::time::Duration;

use aobake_e2e::{binary, character, repo};
use serde_json::Value;

use crate::browser::{
    Driver, artifacts, block_on, browser_with, free_port, wait_for, wait_for_port,
};
use crate::util::aobake_bake;

/// `python3 -m http.server` over a folder, killed on drop: module scripts
/// and import maps want HTTP, not file URLs.
struct Site {
    child: Child,
    port: u16,
}

impl Site {
    fn serve(dir: &std::path::Path) -> Self {
        let port = free_port();
        let child = Command::new("python3")
            .args([
                "-m",
                "http.server",
                &port.to_string(),
                "--bind",
                "127.0.0.1",
            ])
            .current_dir(dir)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("python3");
        wait_for_port(port, "the site");
        Self { child, port }
    }
}

impl Drop for Site {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Mean luminance over the pixels the character covers (not the black
/// background in either render).
fn covered_means(with: &[u8], without: &[u8]) -> (f64, f64, usize, usize) {
    let (mut a, mut b, mut n, mut darker) = (0.0, 0.0, 0usize, 0usize);
    for (p, q) in with.chunks_exact(4).zip(without.chunks_exact(4)) {
        let lum = |c: &[u8]| (u32::from(c[0]) + u32::from(c[1]) + u32::from(c[2])) as f64 / 3.0;
        if lum(q) > 0.0 {
            a += lum(p);
            b += lum(q);
            n += 1;
            if lum(p) < 0.8 * lum(q) {
                darker += 1;
            }
        }
    }
    (a / n.max(1) as f64, b / n.max(1) as f64, n, darker)
}

fn write_png(name: &str, rgba: &[u8], size: u32) {
    // WebGL's rows are bottom-up.
    let rows: Vec<u8> = rgba
        .chunks_exact(4 * size as usize)
        .rev()
        .flatten()
        .copied()
        .collect();
    let path = artifacts().join(name);
    let file = std::fs::File::create(&path).unwrap();
    let mut e = png::Encoder::new(std::io::BufWriter::new(file), size, size);
    e.set_color(png::ColorType::Rgba);
    e.set_depth(png::BitDepth::Eight);
    e.write_header().unwrap().write_image_data(&rows).unwrap();
    eprintln!("render: {}", path.display());
}

#[test]
fn a_texel_exports_occlusion_shows_in_a_stock_three_js_render() {
    let three = repo().join("tests/tools/node_modules/three/build/three.module.js");
    assert!(
        three.is_file(),
        "three.js is missing: npm ci --prefix tests/tools (which .ci/run does)"
    );
    let dir = tempfile::tempdir().unwrap();
    let man = character("CesiumMan");
    aobake_bake(
        dir.path(),
        &man,
        &[
            "--method",
            "texel-linear",
            "--poses",
            "48",
            "--samples",
            "16",
            "--eval-poses",
            "2",
            "--eval-fps",
            "5",
            "--param",
            "texel.atlas=128",
        ],
        "man",
    );
    let site = dir.path().join("site");
    std::fs::create_dir_all(&site).unwrap();
    let export = Command::new(binary())
        .arg("export")
        .arg(dir.path().join("man.aob"))
        .arg(&man)
        .arg("--gltf")
        .arg(site.join("man-ao.glb"))
        .output()
        .unwrap();
    assert!(
        export.status.success(),
        "{}",
        String::from_utf8_lossy(&export.stderr)
    );
    std::fs::copy(
        repo().join("tests/tools/three/occlusion.html"),
        site.join("occlusion.html"),
    )
    .unwrap();
    std::os::unix::fs::symlink(
        repo().join("tests/tools/node_modules/three"),
        site.join("three"),
    )
    .unwrap();
    let served = Site::serve(&site);
    let driver = Driver::start();
    let result: Value = block_on(async {
        let c = browser_with(&driver, true).await;
        c.goto(&format!(
            "http://127.0.0.1:{}/occlusion.html?file=man-ao.glb",
            served.port
        ))
        .await
        .unwrap();
        let result = wait_for(
            &c,
            "the three.js render",
            "window.result",
            Duration::from_secs(60),
        )
        .await;
        c.close().await.unwrap();
        result
    });
    assert_eq!(result["ok"], true, "{}", result["error"]);
    eprintln!("three.js r{}", result["revision"]);
    // The loader took the occlusionTexture as the aoMap, on TEXCOORD_1
    // (CesiumMan's own TEXCOORD_0 is its colour map's).
    let maps = result["aoMaps"].as_array().unwrap();
    assert!(!maps.is_empty(), "no aoMap: {result}");
    for m in maps {
        assert_eq!(m["channel"], 1, "{m}");
        // The atlas's page: 128 wide, as tall as its charts need.
        assert_eq!(m["width"].as_u64(), Some(128), "{m}");
        assert!((64..=128).contains(&m["height"].as_u64().unwrap()), "{m}");
    }
    let bytes = |key: &str| -> Vec<u8> {
        result[key]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as u8)
            .collect()
    };
    let (with, without) = (bytes("withAo"), bytes("withoutAo"));
    let size = result["size"].as_u64().unwrap() as u32;
    write_png("three-with-ao.png", &with, size);
    write_png("three-without-ao.png", &without, size);
    let (a, b, covered, darker) = covered_means(&with, &without);
    eprintln!(
        "{covered} pixels on the character: mean {a:.1} with the occlusionTexture, {b:.1} without; {darker} at least 20% darker"
    );
    assert!(covered > 2000, "the character covers {covered} pixels");
    // Darker on the whole, and much darker in its creases, never lighter.
    assert!(a < 0.97 * b, "with {a:.1} against {b:.1}");
    assert!(
        darker * 50 > covered,
        "{darker} of {covered} pixels much darker"
    );
    assert!(
        with.chunks_exact(4)
            .zip(without.chunks_exact(4))
            .all(|(p, q)| p[0] <= q[0].saturating_add(1)),
        "the AO lightened a pixel"
    );
}
