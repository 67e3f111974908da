//! The dashboard in a real headless Chromium, driven over WebDriver
//! (Debian's `chromium` and `chromium-driver`, which `.ci/run` installs):
//! a bake's progress bar advances without a reload, the finished bake
//! shows its report and previews, cancel works, and a read-only token sees
//! the actions disabled with a note saying why. Screenshots are written
//! under `target/tmp/dashboard/` (the path is printed).

use std::time::Duration;

use aobake_e2e::{ADMIN, Options, TestEnv, character};
use fantoccini::{Client, Locator, key::Key};
use serde_json::{Value, json};

use crate::browser::{Driver, artifacts, block_on, browser, browser_with, eval, shot, wait_for};
use crate::util::{quick_params, upload};

fn submit(env: &TestEnv, token: &str, character: &str, poses: usize) -> i64 {
    let (status, b) = env
        .request(
            "POST",
            "/v1/bakes",
            token,
            Some(json!({"character": character, "method": "vertex-linear", "params": quick_params(poses)})),
        )
        .unwrap();
    assert_eq!(status, 202, "{b}");
    b["id"].as_i64().unwrap()
}

/// Every parameter of a bake view as `path → JSON text`, as the compare
/// page lists them.
fn flat_params(v: &Value, prefix: &str, out: &mut Vec<(String, String)>) {
    for (k, x) in v.as_object().into_iter().flatten() {
        let path = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        if x.is_object() {
            flat_params(x, &path, out);
        } else {
            out.push((path, x.to_string()));
        }
    }
}

/// Two versions of a character side by side, reached from the versions
/// page: what they were baked from, the parameters that differ, and each
/// headline figure of their reports with its change, better or worse as
/// the figure goes (PSNR up, RMSE and bytes down); a bake without a
/// report says so instead.
#[test]
fn two_versions_compare_their_parameters_and_quality() {
    let mut env = TestEnv::start(Options::default());
    let driver = Driver::start();
    env.start_worker(&[]);
    let digest = upload(&env, &character("RiggedSimple"));
    let (first, second) = (
        submit(&env, ADMIN, &digest, 8),
        submit(&env, ADMIN, &digest, 12),
    );
    let view = |id: i64| {
        let b = env.wait_bake(id, Duration::from_secs(120));
        assert_eq!(b["state"], "done", "{b}");
        b
    };
    let (va, vb) = (view(first), view(second));
    let report = |id: i64| {
        env.request("GET", &format!("/v1/bakes/{id}/report"), ADMIN, None)
            .unwrap()
            .1
    };
    let (ra, rb) = (report(first), report(second));
    let (mut pa, mut pb) = (Vec::new(), Vec::new());
    flat_params(&va["params"], "", &mut pa);
    flat_params(&vb["params"], "", &mut pb);
    let differ: Vec<&String> = pa
        .iter()
        .filter(|(k, v)| !pb.iter().any(|(l, w)| l == k && w == v))
        .map(|(k, _)| k)
        .collect();
    assert!(differ.iter().any(|k| k.ends_with("poses")), "{differ:?}");
    block_on(async {
        let c = browser(&driver).await;
        c.goto(&format!(
            "{}/#token={ADMIN}&next=/versions/{digest}/vertex-linear",
            env.url
        ))
        .await
        .unwrap();
        let link = format!("tr[data-bake=\"{second}\"] a.compare");
        wait_for(
            &c,
            "the compare link",
            &format!("document.querySelector('{link}')"),
            Duration::from_secs(20),
        )
        .await;
        assert_eq!(
            eval(
                &c,
                &format!("return document.querySelector('tr[data-bake=\"{first}\"] a.compare')")
            )
            .await,
            Value::Null,
            "the first version has none before it"
        );
        c.find(Locator::Css(&link))
            .await
            .unwrap()
            .click()
            .await
            .unwrap();
        wait_for(
            &c,
            "the comparison",
            "document.querySelector('#compare-quality')",
            Duration::from_secs(20),
        )
        .await;
        assert_eq!(
            eval(&c, "return location.hash").await,
            json!(format!("#/compare/{first}/{second}"))
        );
        // A page without an event stream says the server is online, not
        // offline.
        assert_eq!(
            eval(&c, "return document.getElementById('live').textContent").await,
            json!("online")
        );
        let same = eval(&c, "return Object.fromEntries([...document.querySelectorAll('#compare-inputs tr[data-same]')].map(r => [r.dataset.input, r.dataset.same]))").await;
        assert_eq!(
            same,
            json!({"character": "same", "clips": "same", "method": "same"})
        );
        // The parameters that differ, each with both values.
        let listed = eval(&c, "return [...document.querySelectorAll('#params-differ tr[data-param]')].map(r => r.dataset.param)").await;
        let mut want: Vec<&String> = differ.clone();
        want.sort();
        assert_eq!(listed, json!(want));
        let poses = eval(&c, "const r = [...document.querySelectorAll('#params-differ tr[data-param]')].find(r => r.dataset.param.endsWith('poses') && r.dataset.param.split('.').pop() === 'poses'); return r && [...r.querySelectorAll('td')].slice(1).map(td => td.textContent)").await;
        assert_eq!(poses, json!(["8", "12"]));
        // The figures: each change is the reports' difference, judged by
        // the figure's direction.
        let rows = eval(&c, "return [...document.querySelectorAll('#compare-quality tr[data-figure]')].map(r => [r.dataset.figure, Number(r.dataset.change), r.dataset.verdict])").await;
        let rows = rows.as_array().unwrap();
        let figure = |label: &str| {
            rows.iter()
                .find(|r| r[0] == label)
                .unwrap_or_else(|| panic!("no {label:?} in {rows:?}"))
                .clone()
        };
        let psnr = |r: &Value| {
            r["evaluation"]["random_poses"]["model"]["mean"]["psnr_db"]
                .as_f64()
                .unwrap()
        };
        let row = figure("Held-out random poses: model PSNR");
        let d = psnr(&rb) - psnr(&ra);
        assert!(
            (row[1].as_f64().unwrap() - d).abs() < 1e-9,
            "{row} against {d}"
        );
        let verdict = if d > 0.0 {
            "better"
        } else if d < 0.0 {
            "worse"
        } else {
            "same"
        };
        assert_eq!(row[2], verdict, "{row}");
        let bytes = |r: &Value| r["sizes"]["asset_bytes"].as_f64().unwrap();
        let row = figure("Asset bytes");
        let d = bytes(&rb) - bytes(&ra);
        assert_eq!(row[1].as_f64().unwrap(), d, "{row}");
        let verdict = if d < 0.0 {
            "better"
        } else if d > 0.0 {
            "worse"
        } else {
            "same"
        };
        assert_eq!(row[2], verdict, "{row}");
        shot(&c, "compare-versions").await;
        // A bake without a report yet: no figures, and why.
        let third = submit(&env, ADMIN, &digest, 16);
        env.request("POST", &format!("/v1/bakes/{third}/cancel"), ADMIN, None)
            .unwrap();
        c.goto(&format!("{}/#/compare/{first}/{third}", env.url))
            .await
            .unwrap();
        let said = wait_for(&c, "no quality to compare", "document.querySelector('#no-quality') && document.querySelector('#no-quality').textContent", Duration::from_secs(20)).await;
        assert!(
            said.as_str()
                .unwrap()
                .contains(&format!("#{third} (cancelled)")),
            "{said}"
        );
        // A narrow window (a phone): no page scrolls sideways, wide tables
        // scroll inside it.
        c.set_window_size(500, 900).await.unwrap();
        for (page, ready) in [
            (
                "#/".to_owned(),
                "document.querySelector('tr[data-bake] .bar')",
            ),
            (
                format!("#/bakes/{second}"),
                "document.querySelector('#report table')",
            ),
            (
                format!("#/compare/{first}/{second}"),
                "document.querySelector('#compare-quality')",
            ),
        ] {
            c.goto(&format!("{}/{page}", env.url)).await.unwrap();
            wait_for(&c, &page, ready, Duration::from_secs(20)).await;
            let widths = eval(
                &c,
                "return [document.documentElement.scrollWidth, window.innerWidth]",
            )
            .await;
            assert!(
                widths[0].as_u64() <= widths[1].as_u64(),
                "{page} scrolls sideways: {widths}"
            );
            let name = match page.trim_start_matches("#/") {
                "" => "list".to_owned(),
                p => p.replace('/', "-"),
            };
            shot(&c, &format!("narrow-{name}")).await;
        }
    });
}

/// A paused bake's page says the jobs under way finish first (a pause
/// leases nothing new), and stops saying it once they did; a queued
/// bake's page says how many bakes run before it.
#[test]
fn a_paused_bake_says_its_running_jobs_finish_first_and_a_queued_one_its_place() {
    // A lease far longer than the test: the frozen worker keeps its job.
    let mut env = TestEnv::start(Options {
        lease_secs: 60.0,
        ..Options::default()
    });
    let w = env.start_worker(&[]);
    let driver = Driver::start();
    let digest = upload(&env, &character("CesiumMan"));
    let id = submit(&env, ADMIN, &digest, 96);
    // A job under way, its worker frozen so that it stays so.
    env.wait_for_bake(id, Duration::from_secs(60), "run a job", |b| {
        b["jobs"]
            .as_array()
            .is_some_and(|jobs| jobs.iter().any(|j| j["state"] == "running"))
    });
    env.signal_worker(w, nix::sys::signal::Signal::SIGSTOP);
    let (status, paused) = env
        .request("POST", &format!("/v1/bakes/{id}/pause"), ADMIN, None)
        .unwrap();
    assert_eq!(
        (status, &paused["state"]),
        (200, &json!("paused")),
        "{paused}"
    );
    // Two bakes wait in the queue meanwhile (a paused one is not ahead).
    let second = submit(&env, ADMIN, &digest, 8);
    let third = submit(&env, ADMIN, &digest, 16);
    block_on(async {
        let c = browser(&driver).await;
        for (bake, place) in [
            (second, "Queued: it runs next when a worker is free."),
            (
                third,
                "Queued behind 1 bake (higher priority, or as high and older).",
            ),
        ] {
            c.goto(&format!("{}/#token={ADMIN}&next=/bakes/{bake}", env.url))
                .await
                .unwrap();
            // This bake's page, not the one before it.
            let page = format!(
                "document.querySelector('main h1') && document.querySelector('main h1').textContent.startsWith('Bake #{bake} ') && document.querySelector('#queue') && document.querySelector('#queue').textContent"
            );
            let said = wait_for(&c, "the queue's place", &page, Duration::from_secs(20)).await;
            assert_eq!(said, json!(place), "bake {bake}");
        }
        // Raised above the other, the third runs next.
        eval(&c, "const p = document.querySelector('#priority'); p.value = '5'; p.form.requestSubmit(); return null").await;
        wait_for(&c, "the new place", "document.querySelector('#queue').textContent === 'Queued: it runs next when a worker is free.'", Duration::from_secs(20)).await;
        let (_, raised) = env
            .request("GET", &format!("/v1/bakes/{third}"), ADMIN, None)
            .unwrap();
        assert_eq!(raised["priority"], 5, "the server agrees");
        c.goto(&format!("{}/#/bakes/{id}", env.url)).await.unwrap();
        let said = wait_for(
            &c,
            "the pausing note",
            "document.querySelector('#pausing') && document.querySelector('#pausing').textContent",
            Duration::from_secs(20),
        )
        .await;
        assert_eq!(said, json!(" 1 running job finishes first"));
        env.signal_worker(w, nix::sys::signal::Signal::SIGCONT);
        wait_for(&c, "the job finished", "document.querySelector('#state [data-state=\"paused\"]') && !document.querySelector('#pausing')", Duration::from_secs(120)).await;
        c.close().await.unwrap();
    });
}

#[test]
fn the_dashboard_follows_a_bake_live_and_shows_its_results() {
    let mut env = TestEnv::start(Options::default());
    let driver = Driver::start();
    let submitter = env.token(&["read", "submit"]);
    let reader = env.token(&["read"]);
    let digest = upload(&env, &character("CesiumMan"));
    // Queued with no worker yet: the page sees it at 0 first.
    let id = submit(&env, ADMIN, &digest, 24);
    block_on(async {
        let c = browser(&driver).await;
        // The token travels in the fragment and leaves the address bar.
        c.goto(&format!("{}/#token={submitter}", env.url))
            .await
            .unwrap();
        let row = format!("document.querySelector('tr[data-bake=\"{id}\"] .bar')");
        wait_for(&c, "the bakes list", &row, Duration::from_secs(20)).await;
        // Characters by the name they were uploaded under, not a digest.
        let label = format!("document.querySelector('tr[data-bake=\"{id}\"] .character')");
        let name = wait_for(
            &c,
            "the character's name",
            &format!("{label}.dataset.named === 'yes' && {label}.textContent"),
            Duration::from_secs(20),
        )
        .await;
        assert_eq!(name, json!("CesiumMan.glb"));
        let url = c.current_url().await.unwrap();
        assert!(!url.as_str().contains(&submitter), "{url}");
        let text = eval(&c, "return document.body.innerText").await;
        assert!(!text.as_str().unwrap().contains("null"), "{text}");
        let done0 = eval(&c, &format!("return Number({row}.dataset.done)")).await;
        assert_eq!(done0, json!(0));
        // What a person sees: an empty bar (its width is 0 px).
        let width = eval(
            &c,
            &format!("return {row}.firstChild.getBoundingClientRect().width"),
        )
        .await;
        assert_eq!(width.as_f64(), Some(0.0), "a queued bake's bar is empty");
        shot(&c, "1-bakes-queued").await;

        // The bake page: a marker on the window survives only if the page
        // is never reloaded.
        c.goto(&format!("{}/#/bakes/{id}", env.url)).await.unwrap();
        wait_for(
            &c,
            "the bake page",
            "document.querySelector('#jobs')",
            Duration::from_secs(20),
        )
        .await;
        wait_for(
            &c,
            "the live stream",
            "document.querySelector('#live.on')",
            Duration::from_secs(20),
        )
        .await;
        eval(&c, "window.__notReloaded = true; return null").await;
        // A summary by stage; every job folded away.
        let stages = eval(
            &c,
            "return [...document.querySelectorAll('#stages tbody tr')].map(r => r.dataset.stage)",
        )
        .await;
        assert_eq!(stages[0], json!("sample"), "{stages}");
        assert!(
            stages.as_array().unwrap().contains(&json!("fit")),
            "{stages}"
        );
        assert_eq!(
            eval(&c, "return document.querySelector('#all-jobs').open").await,
            json!(false)
        );
        let heading = eval(&c, "return document.querySelector('main h1').textContent").await;
        assert!(
            heading.as_str().unwrap().contains("CesiumMan.glb"),
            "{heading}"
        );
        // The method's own parameters only.
        let params = eval(
            &c,
            "return Object.keys(JSON.parse(document.querySelector('main pre').textContent))",
        )
        .await;
        let params: Vec<&str> = params
            .as_array()
            .unwrap()
            .iter()
            .map(|k| k.as_str().unwrap())
            .collect();
        assert!(
            params.contains(&"linear")
                && !params
                    .iter()
                    .any(|k| ["clustered", "grid", "cubemap"].contains(k)),
            "{params:?}"
        );
        let bar = "document.querySelector('main .bar')";
        env.start_worker(&[]);
        let mid = wait_for(
            &c,
            "progress",
            &format!("Number({bar}.dataset.done) > 0 && Number({bar}.dataset.done) < Number({bar}.dataset.total) && Number({bar}.dataset.done)"),
            Duration::from_secs(120),
        )
        .await;
        eprintln!("progress bar at {mid} without a reload");
        // The running jobs come first, above the folded table, and the
        // time left is estimated from the rate the page measured.
        let active = wait_for(
            &c,
            "a running job listed first",
            "document.querySelector('#active tbody tr') && document.querySelector('#active tbody tr [data-state]').dataset.state",
            Duration::from_secs(60),
        )
        .await;
        assert!(
            active == json!("running") || active == json!("retryable") || active == json!("dead"),
            "{active}"
        );
        let eta = wait_for(&c, "an estimate of the time left", "/ left \\(/.test(document.querySelector('#eta').textContent) && document.querySelector('#eta').textContent", Duration::from_secs(60)).await;
        eprintln!("{eta}");
        wait_for(
            &c,
            "the jobs table to follow",
            "document.querySelector('#jobs [data-state=\"completed\"]')",
            Duration::from_secs(60),
        )
        .await;
        shot(&c, "2-bake-running").await;
        wait_for(
            &c,
            "the finished bake",
            "document.querySelector('#state [data-state=\"done\"]')",
            Duration::from_secs(300),
        )
        .await;
        // Report and previews, their images decoded.
        wait_for(
            &c,
            "the report",
            "document.querySelector('#report table')",
            Duration::from_secs(30),
        )
        .await;
        let images = "[...document.querySelectorAll('#previews img')]";
        let loaded = wait_for(
            &c,
            "the previews",
            &format!("{images}.length >= 4 && {images}.every(i => i.complete && i.naturalWidth > 0) && {images}.length"),
            Duration::from_secs(30),
        )
        .await;
        assert_eq!(loaded, json!(4), "three stills and an animation");
        let kinds = eval(
            &c,
            &format!("return {images}.map(i => i.closest('figure').dataset.kind)"),
        )
        .await;
        assert_eq!(kinds, json!(["still", "still", "still", "animation"]));
        // Each still carries the screen-space baseline beside the model:
        // the character's row has both RMSEs as numbers.
        let screen = eval(
            &c,
            "return [...document.querySelectorAll('#previews figure[data-kind=\"still\"]')].map(f => { const r = [...f.querySelectorAll('.screen-space-errors tr')].find(t => t.querySelector('td.num')); return r ? [...r.querySelectorAll('td.num')].slice(0, 2).map(td => Number(td.textContent)) : null; })",
        )
        .await;
        let rows = screen.as_array().unwrap();
        assert_eq!(rows.len(), 3, "{screen}");
        for row in rows {
            let values = row
                .as_array()
                .unwrap_or_else(|| panic!("a still without its baseline: {screen}"));
            assert!(
                values.len() == 2
                    && values
                        .iter()
                        .all(|v| v.as_f64().is_some_and(|x| x > 0.0 && x < 1.0)),
                "model and GTAO RMSE: {screen}"
            );
        }
        // What the bake found, at the top: its gain and the per-pixel
        // comparison with screen-space AO, numbers from the report and the
        // stills; the bar's count with its percentage.
        let headline = eval(&c, "return [document.querySelector('#headline-gain')?.textContent, document.querySelector('#headline-pixels')?.textContent, document.querySelector('#count').textContent]").await;
        let gain = headline[0].as_str().unwrap_or_default();
        let per_pixel = headline[1].as_str().unwrap_or_default();
        assert!(
            gain.starts_with("Over the static average: ")
                && gain.contains(" dB on frames of its training clips"),
            "{headline}"
        );
        assert!(
            per_pixel.contains("from ray-traced AO") && per_pixel.contains("GTAO"),
            "{headline}"
        );
        let count = headline[2].as_str().unwrap_or_default();
        assert!(count.ends_with("(100%)"), "{headline}");
        // The stills pooled per pixel above them: one row for the clip,
        // its model RMSE between the stills' own.
        let pooled = eval(
            &c,
            "return [...document.querySelectorAll('#pixels tbody tr')].map(r => [...r.querySelectorAll('td')].map(td => td.textContent))",
        )
        .await;
        let pooled = pooled.as_array().unwrap();
        assert_eq!(pooled.len(), 1, "{pooled:?}");
        let cell = |i: usize| pooled[0][i].as_str().unwrap().parse::<f64>().unwrap();
        let stills_model: Vec<f64> = rows.iter().map(|r| r[0].as_f64().unwrap()).collect();
        let (lo, hi) = stills_model
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &x| (a.min(x), b.max(x)));
        assert_eq!(cell(2), 3.0, "three stills pooled: {pooled:?}");
        assert!(
            cell(3) >= lo - 1e-4 && cell(3) <= hi + 1e-4,
            "pooled {} against the stills' {stills_model:?}",
            cell(3)
        );
        // A vertex asset does not shade the ground: each still says so
        // under its table, not only in the dash's tooltip.
        let notes = eval(&c, "return [...document.querySelectorAll('#previews figure[data-kind=\"still\"] .not-judged')].map(p => p.textContent)").await;
        let notes = notes.as_array().unwrap();
        assert_eq!(notes.len(), 3, "{notes:?}");
        for note in notes {
            assert!(
                note.as_str()
                    .unwrap()
                    .contains("on the ground is not judged: a vertex asset shades the character"),
                "{note}"
            );
        }
        let plot = eval(
            &c,
            "const i = document.querySelector('#report img'); return i && i.naturalWidth",
        )
        .await;
        assert!(
            plot.as_u64().unwrap_or(0) > 100,
            "the PSNR plot shows: {plot}"
        );
        let caption = eval(
            &c,
            "return document.querySelector('#report figcaption').textContent",
        )
        .await;
        assert!(
            caption.as_str().unwrap().contains("training clips"),
            "{caption}"
        );
        // Done: every stage's jobs are done, and no time is left.
        let counted = eval(&c, "return [...document.querySelectorAll('#stages [data-count=\"done\"]')].reduce((n, td) => n + Number(td.textContent), 0) === document.querySelectorAll('#jobs tbody tr').length").await;
        assert_eq!(counted, json!(true));
        assert_eq!(
            eval(&c, "return document.querySelector('#eta').textContent").await,
            json!("")
        );
        assert_eq!(
            eval(&c, "return window.__notReloaded === true").await,
            json!(true)
        );
        let jobs = eval(&c, "return [...document.querySelectorAll('#jobs [data-state]')].every(b => b.dataset.state === 'completed')").await;
        assert_eq!(jobs, json!(true), "every job shows completed");
        // No leaked "null" (the parameters' JSON may hold real nulls).
        let text = eval(&c, "return [...document.querySelectorAll('main > :not(pre)')].map(e => e.innerText).join('\\n')").await;
        assert!(!text.as_str().unwrap().contains("null"), "{text}");
        shot(&c, "3-bake-done").await;
        eval(
            &c,
            "document.querySelector('#report').scrollIntoView(); return null",
        )
        .await;
        shot(&c, "3b-bake-report").await;

        // Cancel: a second bake, cancelled from its page.
        let other = submit(&env, ADMIN, &digest, 40);
        c.goto(&format!("{}/#/bakes/{other}", env.url))
            .await
            .unwrap();
        let cancel = "document.querySelector('button[data-action=\"cancel\"]')";
        wait_for(
            &c,
            "the cancel button",
            &format!("{cancel} && !{cancel}.disabled"),
            Duration::from_secs(20),
        )
        .await;
        // Cancel asks first: dismissed, nothing happens; accepted, the
        // bake is cancelled.
        let cancel_button = c
            .find(Locator::Css("button[data-action=\"cancel\"]"))
            .await
            .unwrap();
        cancel_button.click().await.unwrap();
        let asked = c.get_alert_text().await.unwrap();
        assert!(
            asked.starts_with(&format!("Cancel bake #{other}?")),
            "{asked}"
        );
        c.dismiss_alert().await.unwrap();
        std::thread::sleep(Duration::from_millis(500));
        let (_, b) = env
            .request("GET", &format!("/v1/bakes/{other}"), ADMIN, None)
            .unwrap();
        assert_ne!(b["state"], "cancelled", "a dismissed cancel cancelled");
        cancel_button.click().await.unwrap();
        c.accept_alert().await.unwrap();
        wait_for(
            &c,
            "the cancelled state",
            "document.querySelector('#state [data-state=\"cancelled\"]')",
            Duration::from_secs(20),
        )
        .await;
        let (_, b) = env
            .request("GET", &format!("/v1/bakes/{other}"), ADMIN, None)
            .unwrap();
        assert_eq!(b["state"], "cancelled", "the server agrees");
        // Its cancelled jobs are counted in a column of their own, and the
        // numbers' headers sit over them (right-aligned like the cells).
        let cancelled = wait_for(&c, "the cancelled jobs counted", "[...document.querySelectorAll('#stages [data-count=\"cancelled\"]')].reduce((n, td) => n + Number(td.textContent), 0)", Duration::from_secs(20)).await;
        let listed = b["jobs"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|j| j["state"] == "cancelled")
            .count();
        assert_eq!(cancelled, json!(listed), "{b}");
        // Its parameters as they were given (f32 values without f64 noise).
        let params = wait_for(
            &c,
            "the parameters",
            "document.querySelector('#params') && document.querySelector('#params').textContent",
            Duration::from_secs(20),
        )
        .await;
        assert!(
            params.as_str().unwrap().contains("\"range_margin\": 0.1,"),
            "{params}"
        );
        let aligned = eval(&c, "return [...document.querySelectorAll('#stages thead th')].map(th => th.classList.contains('num'))").await;
        assert_eq!(
            aligned,
            json!([false, true, true, true, true, true, true, true, true])
        );
        shot(&c, "4-bake-cancelled").await;

        // Workers: the one worker, with its tracer and last heartbeat.
        c.goto(&format!("{}/#/workers", env.url)).await.unwrap();
        wait_for(
            &c,
            "the workers",
            "document.querySelectorAll('tr[data-worker]').length === 1",
            Duration::from_secs(20),
        )
        .await;
        let tracer = eval(
            &c,
            "return document.querySelector('tr[data-worker] td.tracer').textContent",
        )
        .await;
        let (_, workers) = env.request("GET", "/v1/workers", ADMIN, None).unwrap();
        assert_eq!(tracer, workers[0]["tracer"], "the tracer the worker told");
        shot(&c, "5-workers").await;

        // Versions of the character and method: both bakes, newest first.
        c.goto(&format!("{}/#/versions/{digest}/vertex-linear", env.url))
            .await
            .unwrap();
        let versions = wait_for(
            &c,
            "the versions",
            "document.querySelectorAll('main tbody tr').length === 2 && [...document.querySelectorAll('main tbody tr td:nth-child(2) a')].map(a => a.textContent)",
            Duration::from_secs(20),
        )
        .await;
        assert_eq!(versions, json!([format!("#{other}"), format!("#{id}")]));
        let heading = wait_for(&c, "the named versions", "document.querySelector('main h1 .character').dataset.named === 'yes' && document.querySelector('main h1').textContent", Duration::from_secs(20)).await;
        assert!(
            heading
                .as_str()
                .unwrap()
                .starts_with("Versions of CesiumMan.glb"),
            "{heading}"
        );

        // The URL `serve --demo` prints opens the bake itself, with any
        // token the server accepts (this one is not hex).
        c.goto(&format!("{}/#token={ADMIN}&next=/bakes/{id}", env.url))
            .await
            .unwrap();
        wait_for(
            &c,
            "the bake page from a sign-in link",
            &format!("location.hash === '#/bakes/{id}' && document.querySelector('#stages')"),
            Duration::from_secs(20),
        )
        .await;
        let who = eval(&c, "return document.getElementById('who').textContent").await;
        assert!(who.as_str().unwrap().contains("admin"), "{who}");

        // A read-only token sees the bakes, the actions disabled and why.
        c.goto(&format!("{}/#token={reader}", env.url))
            .await
            .unwrap();
        wait_for(&c, "the bakes list", &row, Duration::from_secs(20)).await;
        c.goto(&format!("{}/#/bakes/{id}", env.url)).await.unwrap();
        wait_for(
            &c,
            "the read-only note",
            "document.querySelector('#read-only')",
            Duration::from_secs(20),
        )
        .await;
        let disabled = eval(
            &c,
            "return ['cancel','pause','resume','retry'].map(a => document.querySelector(`button[data-action=\"${a}\"]`).disabled)",
        )
        .await;
        assert_eq!(disabled, json!([true, true, true, true]));
        // Readable (WCAG AA, 4.5:1 for text this size): a disabled
        // button's label and the live pill's.
        wait_for(
            &c,
            "the live stream",
            "document.querySelector('#live.on')",
            Duration::from_secs(20),
        )
        .await;
        let contrast = eval(&c, r#"
            const rgb = (s) => s.match(/[\d.]+/g).slice(0, 3).map(Number);
            const lum = ([r, g, b]) => {
              const f = (c) => { c /= 255; return c <= 0.03928 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4; };
              return 0.2126 * f(r) + 0.7152 * f(g) + 0.0722 * f(b);
            };
            const back = (el) => {
              for (; el; el = el.parentElement) {
                const c = getComputedStyle(el).backgroundColor;
                if (c !== 'transparent' && !/rgba\(.*,\s*0\)$/.test(c)) return c;
              }
              return 'rgb(255, 255, 255)';
            };
            const ratio = (el) => {
              const a = lum(rgb(getComputedStyle(el).color)), b = lum(rgb(back(el)));
              return (Math.max(a, b) + 0.05) / (Math.min(a, b) + 0.05);
            };
            return [ratio(document.querySelector('button[data-action="cancel"]')), ratio(document.getElementById('live'))];
        "#).await;
        for r in contrast.as_array().unwrap() {
            assert!(r.as_f64().unwrap() >= 4.5, "{contrast}");
        }
        let download = eval(
            &c,
            "return document.querySelector('button[data-action=\"download\"]').disabled",
        )
        .await;
        assert_eq!(download, json!(false), "reading the asset needs only read");
        wait_for(
            &c,
            "the previews",
            &format!("{images}.length === 4"),
            Duration::from_secs(30),
        )
        .await;
        // The viewer shows the mesh, the studio's source: not to `read`.
        let note = eval(
            &c,
            "return document.querySelector('#viewer-status').textContent",
        )
        .await;
        assert!(note.as_str().unwrap().contains("submit scope"), "{note}");
        shot(&c, "6-read-only").await;

        // Signing out stops the page: the stream goes offline, and a bake
        // that moves meanwhile does not redraw the form under the typing.
        c.find(Locator::Css("#who a"))
            .await
            .unwrap()
            .click()
            .await
            .unwrap();
        wait_for(
            &c,
            "the sign-in form",
            "document.querySelector('form.login')",
            Duration::from_secs(20),
        )
        .await;
        eval(
            &c,
            "document.querySelector('form.login input').value = 'half typed'; return null",
        )
        .await;
        submit(&env, ADMIN, &digest, 8);
        std::thread::sleep(Duration::from_secs(2));
        let state = eval(&c, "return [document.getElementById('live').textContent, document.querySelector('form.login input').value, !!document.querySelector('main .error')]").await;
        assert_eq!(state, json!(["offline", "half typed", false]));
        // A sign-in link pasted into the sign-in page signs in.
        eval(
            &c,
            &format!("location.hash = '#token={reader}&next=/workers'; return null"),
        )
        .await;
        wait_for(
            &c,
            "the workers page from a link",
            "location.hash === '#/workers' && document.querySelector('tr[data-worker]')",
            Duration::from_secs(20),
        )
        .await;
        // A token the server refuses says why (here: it expired).
        let (_, brief) = env
            .request(
                "POST",
                "/v1/tokens",
                ADMIN,
                Some(json!({"name": "brief", "scopes": ["read"], "expires_in_secs": 1})),
            )
            .unwrap();
        std::thread::sleep(Duration::from_millis(1500));
        let brief = brief["token"].as_str().unwrap();
        eval(
            &c,
            &format!("location.hash = '#token={brief}'; return null"),
        )
        .await;
        let said = wait_for(&c, "the refusal's reason", "document.querySelector('form.login') && document.querySelector('main .error') && document.querySelector('main .error').textContent", Duration::from_secs(20)).await;
        assert!(said.as_str().unwrap().contains("expired at"), "{said}");
        c.goto(&format!("{}/#token={reader}", env.url))
            .await
            .unwrap();
        wait_for(&c, "signed in again", &row, Duration::from_secs(20)).await;
        // An address that names no bake says so.
        c.goto(&format!("{}/#/bakes/abc", env.url)).await.unwrap();
        let h1 = wait_for(&c, "the no-such-bake page", "document.querySelector('main h1').textContent === 'No such bake' && document.querySelector('main').innerText", Duration::from_secs(20)).await;
        assert!(h1.as_str().unwrap().contains("not a bake number"), "{h1}");

        // A grid bake's page: its parts, every variant and the slices.
        let truck = upload(&env, &character("CesiumMilkTruck"));
        let (status, b) = env
            .request(
                "POST",
                "/v1/bakes",
                ADMIN,
                Some(
                    json!({"character": truck, "method": "grid", "params": {"grid": {
                    "resolution": 16, "rays": 64, "eval_frames": 2, "eval_ground": 64,
                    "eval_rays": 32, "average_frames": 2}}}),
                ),
            )
            .unwrap();
        assert_eq!(status, 202, "{b}");
        let grid = b["id"].as_i64().unwrap();
        c.goto(&format!("{}/#/bakes/{grid}", env.url))
            .await
            .unwrap();
        wait_for(
            &c,
            "the finished grid bake",
            "document.querySelector('#state [data-state=\"done\"]')",
            Duration::from_secs(300),
        )
        .await;
        let rows = wait_for(
            &c,
            "the grid report",
            "document.querySelectorAll('#report table').length === 2 && [...document.querySelectorAll('#report table')].map(t => t.tBodies[0].rows.length)",
            Duration::from_secs(30),
        )
        .await;
        assert_eq!(rows, json!([3, 9]), "three parts, nine variants");
        let first = eval(&c, "return document.querySelectorAll('#report table')[1].tBodies[0].rows[0].cells[0].textContent").await;
        assert_eq!(first, json!("grids on a static base (cones)"));
        let plot = eval(&c, "const i = document.querySelector('#report img'); return i && i.complete && i.naturalWidth").await;
        assert!(plot.as_u64().unwrap_or(0) > 100, "the slices show: {plot}");
        wait_for(
            &c,
            "the grid previews",
            &format!("{images}.length === 4"),
            Duration::from_secs(30),
        )
        .await;
        let text = eval(&c, "return [...document.querySelectorAll('main > :not(pre)')].map(e => e.innerText).join('\\n')").await;
        assert!(
            !text.as_str().unwrap().contains("null")
                && !text.as_str().unwrap().contains("undefined"),
            "{text}"
        );
        eval(
            &c,
            "document.querySelector('#report').scrollIntoView(); return null",
        )
        .await;
        shot(&c, "7-grid-report").await;

        // A cubemap bake's charts show at their own size, in a frame that
        // scrolls, and fit the page on request.
        let man = upload(&env, &character("CesiumMan"));
        let (status, b) = env
            .request(
                "POST",
                "/v1/bakes",
                ADMIN,
                Some(
                    json!({"character": man, "method": "cubemap-discrete", "params": {"cubemap": {
                    "resolution": 16, "shells": 4, "times": 16, "rays": 16, "eval_times": 2,
                    "eval_points": 64, "eval_ground": 64, "eval_rays": 16}}}),
                ),
            )
            .unwrap();
        assert_eq!(status, 202, "{b}");
        let cube = b["id"].as_i64().unwrap();
        c.goto(&format!("{}/#/bakes/{cube}", env.url))
            .await
            .unwrap();
        wait_for(
            &c,
            "the finished cubemap bake",
            "document.querySelector('#state [data-state=\"done\"]')",
            Duration::from_secs(300),
        )
        .await;
        let chart = "document.querySelector('#report figure.zoom img')";
        let sizes = wait_for(
            &c,
            "the charts",
            &format!("{chart} && {chart}.complete && {chart}.naturalWidth > 0 && [{chart}.naturalWidth, Math.round({chart}.getBoundingClientRect().width)]"),
            Duration::from_secs(30),
        )
        .await;
        assert_eq!(sizes[0], sizes[1], "shown at its own size");
        c.find(Locator::Css("button[data-action=\"zoom\"]"))
            .await
            .unwrap()
            .click()
            .await
            .unwrap();
        let fitted = eval(&c, &format!("return {chart}.getBoundingClientRect().width <= {chart}.closest('figure').getBoundingClientRect().width")).await;
        assert_eq!(fitted, json!(true), "fitted to the page");
        eval(
            &c,
            "document.querySelector('#report').scrollIntoView(); return null",
        )
        .await;
        shot(&c, "7b-cubemap-charts").await;

        // A character with three clips: its report leads with the clips
        // the model never saw (leave one clip out), then the frames of
        // its training clips.
        let fox = upload(&env, &character("Fox"));
        let (status, b) = env
            .request(
                "POST",
                "/v1/bakes",
                ADMIN,
                Some(json!({"character": fox, "method": "vertex-linear", "params": quick_params(24)})),
            )
            .unwrap();
        assert_eq!(status, 202, "{b}");
        let fox_bake = b["id"].as_i64().unwrap();
        c.goto(&format!("{}/#/bakes/{fox_bake}", env.url))
            .await
            .unwrap();
        wait_for(
            &c,
            "the finished Fox bake",
            "document.querySelector('#state [data-state=\"done\"]')",
            Duration::from_secs(300),
        )
        .await;
        let rows = wait_for(
            &c,
            "the unseen clips",
            "document.querySelector('#unseen') && [...document.querySelectorAll('#report tbody tr')].map(r => [r.cells[0].textContent, parseFloat(r.cells[8].textContent)])",
            Duration::from_secs(30),
        )
        .await;
        let rows = rows.as_array().unwrap();
        let names: Vec<&str> = rows.iter().map(|r| r[0].as_str().unwrap()).collect();
        let mut folds = names[..3].to_vec();
        folds.sort_unstable();
        assert_eq!(
            folds,
            [
                "unseen clip Run (refitted without it)",
                "unseen clip Survey (refitted without it)",
                "unseen clip Walk (refitted without it)",
            ],
            "{rows:?}"
        );
        assert_eq!(
            names[3..],
            [
                "frames of the training clips, fresh rays",
                "held-out random poses"
            ]
        );
        // The worst left-out clip first, by its gain over the static
        // average, and the headline names it.
        let gains: Vec<f64> = rows[..3].iter().map(|r| r[1].as_f64().unwrap()).collect();
        assert!(gains.windows(2).all(|w| w[0] <= w[1]), "{rows:?}");
        let gain = eval(
            &c,
            "return document.querySelector('#headline-gain').textContent",
        )
        .await;
        let worst = names[0]
            .trim_start_matches("unseen clip ")
            .trim_end_matches(" (refitted without it)");
        assert!(
            gain.as_str().unwrap().contains(&format!(
                "on {worst}, the clip it never saw that it does worst on"
            )),
            "{gain}"
        );
        let note = eval(&c, "return document.querySelector('#unseen').textContent").await;
        assert!(note.as_str().unwrap().contains("3 folds"), "{note}");
        // The default reference poses: the fit chose its rows, and says
        // which, with the three scores.
        let reference = eval(
            &c,
            "return document.querySelector('#reference').textContent",
        )
        .await;
        let reference = reference.as_str().unwrap();
        assert!(
            reference.starts_with("Reference poses: ")
                && reference.contains("chosen by cross-validation over clips")
                && reference.contains("random poses and clip frames ")
                && reference.contains("clip frames and perturbed frames ")
                && reference.contains("all three ")
                && reference.matches(" dB").count() == 3,
            "{reference}"
        );
        // And the basis its cross-validation chose, among 1 to 32 rows at
        // five thresholds.
        let basis = eval(&c, "return document.querySelector('#basis').textContent").await;
        let basis = basis.as_str().unwrap();
        let rank: usize = basis
            .strip_prefix("Eigen-AO basis: ")
            .and_then(|b| b.split(' ').next())
            .and_then(|r| r.parse().ok())
            .unwrap_or_else(|| panic!("{basis}"));
        assert!(
            (1..=32).contains(&rank)
                && basis.contains(" multiply-adds a vertex), the cheapest of 160 candidates within 0.1 dB of the best on left-out clips")
                && basis.ends_with(" dB at best)."),
            "{basis}"
        );
        shot(&c, "8-unseen-clips").await;
        c.close().await.unwrap();
    });
}

/// An RGBA image.
struct Rgba {
    width: u32,
    height: u32,
    rgba: Vec<u8>,
}

impl Rgba {
    fn read_png(path: &std::path::Path) -> Self {
        let mut decoder = png::Decoder::new(std::io::BufReader::new(
            std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
        ));
        decoder.set_transformations(png::Transformations::EXPAND);
        let mut reader = decoder.read_info().unwrap();
        let mut data = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut data).unwrap();
        let rgba = match info.color_type {
            png::ColorType::Rgba => data,
            png::ColorType::Rgb => data
                .chunks_exact(3)
                .flat_map(|p| [p[0], p[1], p[2], 255])
                .collect(),
            other => panic!("{}: {other:?}", path.display()),
        };
        Self {
            width: info.width,
            height: info.height,
            rgba,
        }
    }

    /// The `size`² square at (`x`, `y`).
    fn crop(&self, x: u32, y: u32, size: u32) -> Self {
        let mut rgba = Vec::with_capacity((4 * size * size) as usize);
        for row in y..y + size {
            let at = (4 * (row * self.width + x)) as usize;
            rgba.extend_from_slice(&self.rgba[at..at + 4 * size as usize]);
        }
        Self {
            width: size,
            height: size,
            rgba,
        }
    }

    fn write_png(&self, path: &std::path::Path) {
        let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
        let mut encoder = png::Encoder::new(file, self.width, self.height);
        encoder.set_color(png::ColorType::Rgba);
        encoder.set_depth(png::BitDepth::Eight);
        encoder
            .write_header()
            .unwrap()
            .write_image_data(&self.rgba)
            .unwrap();
    }

    /// The shares of colour channels that differ by more than the render
    /// tests' ±6 and by more than ±96, and the largest difference.
    fn differ(&self, other: &Self) -> (f64, f64, u8) {
        assert_eq!((self.width, self.height), (other.width, other.height));
        let (mut over, mut far, mut channels, mut worst) = (0usize, 0usize, 0usize, 0u8);
        for (a, b) in self.rgba.chunks_exact(4).zip(other.rgba.chunks_exact(4)) {
            for k in 0..3 {
                let d = a[k].abs_diff(b[k]);
                worst = worst.max(d);
                over += usize::from(d > RENDER_TOLERANCE);
                far += usize::from(d > EDGE_TOLERANCE);
                channels += 1;
            }
        }
        (
            over as f64 / channels as f64,
            far as f64 / channels as f64,
            worst,
        )
    }
}

/// The render tests' tolerance (worker/tests/integration/preview.rs): a
/// channel may differ by ±6, up to 3 % of them by more, at the
/// multisampled edges, which another rasteriser covers differently.
const RENDER_TOLERANCE: u8 = 6;
const EDGE_SHARE: f64 = 0.03;
/// The viewer's own bound at edges, in place of the render tests' worst
/// channel of 96: Chromium's SwiftShader places its four samples where
/// Mesa does not, so an edge pixel can be covered by three samples in one
/// and none in the other; on the error panel's saturated blue beside white
/// (202 levels apart) that moves a channel by 150. At most 0.1 % of the
/// channels may differ by more than 96 (measured: 0.04 % at worst).
const EDGE_TOLERANCE: u8 = 96;
const FAR_SHARE: f64 = 0.001;

/// The viewer's canvas, read back.
async fn viewer_pixels(c: &Client) -> Rgba {
    let v = eval(
        c,
        "return document.querySelector('#viewer canvas').viewer.pixels()",
    )
    .await;
    use base64::Engine as _;
    let rgba = base64::engine::general_purpose::STANDARD
        .decode(v["rgba"].as_str().unwrap())
        .unwrap();
    Rgba {
        width: v["width"].as_u64().unwrap() as u32,
        height: v["height"].as_u64().unwrap() as u32,
        rgba,
    }
}

/// Shows `mode` at the clip's time `time` from the previews' camera in a
/// panel of the previews' size.
async fn viewer_show(c: &Client, clip: &str, time: f32, mode: &str) -> Value {
    let script = format!(
        "const done = arguments[arguments.length - 1];
         document.querySelector('#viewer canvas').viewer
           .show({{clip: {clip:?}, time: {time}, mode: {mode:?}, size: {}}})
           .then(done, (e) => done({{error: String(e)}}));",
        aobake_core::bake::preview::STILL_PANEL
    );
    let shown = c.execute_async(&script, vec![]).await.unwrap();
    assert!(shown.get("error").is_none(), "{shown}");
    shown
}

/// `aobake preview`'s still of `asset` (baked for `character`) at `time`
/// of `clip`, in the test's artifacts.
fn aobake_preview(
    env: &TestEnv,
    name: &str,
    asset: &str,
    character: &std::path::Path,
    clip: &str,
    time: f32,
) -> Rgba {
    let dir = artifacts();
    let path = dir.join(format!("viewer-{name}.aob"));
    let out = env.aobake(&["fetch", "--key", asset, "--out", path.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let still = dir.join(format!("viewer-{name}-aobake-preview.png"));
    let out = env.aobake(&[
        "preview",
        path.to_str().unwrap(),
        character.to_str().unwrap(),
        "--clip",
        clip,
        "--time",
        &time.to_string(),
        "--out",
        still.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    Rgba::read_png(&still)
}

/// Opens bake `id`'s page and waits for its viewer; returns the clip it
/// shows first (the previews').
async fn open_viewer(c: &Client, env: &TestEnv, id: i64) -> String {
    c.goto(&format!("{}/#token={ADMIN}&next=/bakes/{id}", env.url))
        .await
        .unwrap();
    let viewer = format!("document.querySelector('#viewer[data-bake=\"{id}\"]')");
    let status = format!("({viewer} && {viewer}.querySelector('#viewer-status'))");
    wait_for(
        c,
        "the viewer",
        &format!("(({viewer} && {viewer}.dataset.ready === 'yes') || /failed|no WebGL2/.test({status} && {status}.textContent)) && {status}.textContent"),
        Duration::from_secs(60),
    )
    .await;
    let ready = eval(c, &format!("return {viewer}.dataset.ready")).await;
    let text = eval(c, &format!("return {status}.textContent")).await;
    assert_eq!(ready, json!("yes"), "{text}");
    let clip = eval(
        c,
        "return document.querySelector('#viewer canvas').viewer.state().clip",
    )
    .await;
    clip.as_str().unwrap().to_owned()
}

/// At the first still's time of the previews' clip and from the
/// previews' camera, each of the viewer's truth, model and error matches
/// its panel of `aobake preview` within the render tests' tolerance.
async fn viewer_matches_aobake_preview(
    c: &Client,
    env: &TestEnv,
    name: &str,
    bake: &Value,
    character: &std::path::Path,
    clip: &str,
) -> Rgba {
    // The previews' first still: 0.15 of the clip, a frame with truth.
    let length = eval(
        c,
        "return document.querySelector('#viewer canvas').viewer.state().duration",
    )
    .await;
    let wanted = aobake_core::bake::preview::STILL_FRACTIONS[0] * length.as_f64().unwrap() as f32;
    let shown = viewer_show(c, clip, wanted, "truth").await;
    assert_eq!(
        shown["truth"],
        json!(true),
        "the still's frame has its truth: {shown}"
    );
    let time = shown["time"].as_f64().unwrap() as f32;
    let still = aobake_preview(
        env,
        name,
        bake["key"].as_str().unwrap(),
        character,
        clip,
        time,
    );
    let panel = aobake_core::bake::preview::STILL_PANEL;
    // Panels sit under a 30-pixel title row: truth, model, screen-space
    // AO, error.
    let preview_panel = |k: u32| still.crop(k * panel, 30, panel);
    let dir = artifacts();
    let mut model = None;
    for (k, mode) in [(0, "truth"), (1, "model"), (3, "error")] {
        viewer_show(c, clip, time, mode).await;
        let mine = viewer_pixels(c).await;
        mine.write_png(&dir.join(format!("viewer-{name}-{mode}.png")));
        let theirs = preview_panel(k);
        theirs.write_png(&dir.join(format!("viewer-{name}-preview-{mode}.png")));
        let (share, far, worst) = mine.differ(&theirs);
        eprintln!(
            "{name}: the viewer's {mode} against aobake preview at {time} s: {share:.4} of channels over ±{RENDER_TOLERANCE}, {far:.5} over ±{EDGE_TOLERANCE}, worst {worst} (in {})",
            dir.display()
        );
        assert!(
            share <= EDGE_SHARE && far <= FAR_SHARE,
            "{name}: the viewer's {mode} differs from aobake preview's panel: {share:.4} of channels over ±{RENDER_TOLERANCE}, {far:.5} over ±{EDGE_TOLERANCE} (images in {})",
            dir.display()
        );
        if mode == "model" {
            model = Some(mine);
        }
    }
    // Without AO the same frame is not the model's: the comparison above
    // sees the model's AO.
    viewer_show(c, clip, time, "none").await;
    let (share, _, _) = viewer_pixels(c).await.differ(&preview_panel(1));
    assert!(
        share > EDGE_SHARE,
        "{name}: no AO passes for the model: {share}"
    );
    let error = eval(
        c,
        "return document.querySelector('#viewer-error').textContent",
    )
    .await;
    assert!(error.as_str().unwrap().contains("RMSE"), "{error}");
    model.unwrap()
}

#[test]
fn the_viewer_plays_every_method_and_matches_aobake_preview() {
    let mut env = TestEnv::start(Options::default());
    let driver = Driver::start();
    let man = character("CesiumMan");
    let truck = character("CesiumMilkTruck");
    let man_digest = upload(&env, &man);
    let truck_digest = upload(&env, &truck);
    let bakes = [
        (
            "vertex-linear",
            &man,
            json!({"character": man_digest, "method": "vertex-linear", "params": quick_params(24)}),
        ),
        (
            "grid",
            &truck,
            json!({"character": truck_digest, "method": "grid", "params": {"grid": {
            "resolution": 16, "rays": 64, "eval_frames": 2, "eval_ground": 64,
            "eval_rays": 32, "average_frames": 2}}}),
        ),
        (
            "cubemap-discrete",
            &man,
            json!({"character": man_digest, "method": "cubemap-discrete", "params": {"cubemap": {
            "resolution": 16, "shells": 4, "times": 16, "rays": 16, "eval_times": 2,
            "eval_points": 64, "eval_ground": 64, "eval_rays": 16}}}),
        ),
    ];
    let ids: Vec<i64> = bakes
        .iter()
        .map(|(_, _, body)| {
            let (status, b) = env
                .request("POST", "/v1/bakes", ADMIN, Some(body.clone()))
                .unwrap();
            assert_eq!(status, 202, "{b}");
            b["id"].as_i64().unwrap()
        })
        .collect();
    env.start_worker(&[]);
    let done: Vec<Value> = ids
        .iter()
        .map(|&id| env.wait_bake(id, Duration::from_secs(600)))
        .collect();
    for b in &done {
        assert_eq!(b["state"], "done", "{b}");
    }
    block_on(async {
        let c = browser_with(&driver, true).await;
        for (((name, character, _), &id), bake) in bakes.iter().zip(&ids).zip(&done) {
            let clip = open_viewer(&c, &env, id).await;
            let text = eval(
                &c,
                "return document.querySelector('#viewer-status').textContent",
            )
            .await;
            assert!(
                text.as_str().unwrap().starts_with(&format!("{name}: ")),
                "{text}"
            );
            if *name == "vertex-linear" {
                // It plays: the frame moves on by itself.
                let state = "document.querySelector('#viewer canvas').viewer.state()";
                let first = eval(&c, &format!("return {state}.frame")).await;
                wait_for(
                    &c,
                    "the clip to play",
                    &format!("{state}.playing && {state}.frame !== {first}"),
                    Duration::from_secs(20),
                )
                .await;
                shot(&c, "8-viewer-playing").await;
            }
            let model = viewer_matches_aobake_preview(&c, &env, name, bake, character, &clip).await;
            if *name != "vertex-linear" {
                continue;
            }
            // The static average is not the model's AO.
            viewer_show(&c, &clip, 0.3, "static").await;
            let (share, _, worst) = viewer_pixels(&c).await.differ(&model);
            eprintln!(
                "static average against the model: {share:.4} over ±{RENDER_TOLERANCE}, worst {worst}"
            );
            assert!(
                worst > RENDER_TOLERANCE,
                "the static average is the model's AO"
            );
            // The orbit camera: a drag turns the view.
            viewer_show(&c, &clip, 0.3, "model").await;
            eval(&c, "const cv = document.querySelector('#viewer canvas');
                      const at = (type, x) => cv.dispatchEvent(new PointerEvent(type, {clientX: x, clientY: 200, pointerId: 1, bubbles: true}));
                      at('pointerdown', 200); at('pointermove', 260); at('pointerup', 260); return null").await;
            let (share, _, _) = viewer_pixels(&c).await.differ(&model);
            assert!(
                share > EDGE_SHARE,
                "a drag did not turn the camera: {share}"
            );
            // A drag up or down, however far, keeps the eye above the
            // ground (40 px up once put it under).
            for dy in [40, 400, -400] {
                let above = eval(&c, &format!("const cv = document.querySelector('#viewer canvas');
                      const at = (type, y) => cv.dispatchEvent(new PointerEvent(type, {{clientX: 200, clientY: y, pointerId: 1, bubbles: true}}));
                      at('pointerdown', 500); at('pointermove', 500 - {dy}); at('pointerup', 500 - {dy}); return Number(cv.dataset.eyeAboveGround)")).await;
                assert!(
                    above.as_f64().is_some_and(|y| y > 0.0),
                    "a drag of {dy} px up put the eye {above} above the ground"
                );
            }
            // The keyboard: Home goes back to the previews' camera (the
            // model's pixels again), an arrow key turns the view.
            let canvas = c.find(Locator::Css("#viewer canvas")).await.unwrap();
            canvas.send_keys(&Key::Home.to_string()).await.unwrap();
            let (share, _, _) = viewer_pixels(&c).await.differ(&model);
            assert!(
                share <= EDGE_SHARE,
                "Home did not go back to the previews' camera: {share}"
            );
            canvas.send_keys(&Key::Left.to_string()).await.unwrap();
            let (share, _, _) = viewer_pixels(&c).await.differ(&model);
            assert!(
                share > EDGE_SHARE,
                "an arrow key did not turn the camera: {share}"
            );
            c.find(Locator::Css("#viewer-reset"))
                .await
                .unwrap()
                .click()
                .await
                .unwrap();
            shot(&c, "9-viewer-orbited").await;
        }
        // A grid or cubemap bake has no static average in the viewer.
        let disabled = eval(
            &c,
            "return document.querySelector('input[name=viewer-mode][value=static]').disabled",
        )
        .await;
        assert_eq!(disabled, json!(true));
        shot(&c, "10-viewer-cubemap").await;
        c.close().await.unwrap();
    });
}
