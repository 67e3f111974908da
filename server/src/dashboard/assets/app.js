// The aobake dashboard: plain JavaScript against the HTTP API, no build
// step. Live updates come from the API's server-sent events (read with
// fetch, so the bearer token travels in a header, never in a URL); pages
// re-read what an event says has changed (the workers page also every
// 10 s: idle workers poll without any bake changing).
//
// The token comes from the URL fragment (`#token=…`, which browsers do not
// send to servers; `aobake serve --demo` prints such a URL) or from the
// sign-in form, and is kept in this browser's localStorage.

import { viewerSection } from "./viewer.js";

const TOKEN_KEY = "aobake.token";
const main = document.getElementById("main");
let token = localStorage.getItem(TOKEN_KEY);
let me = null; // {name, scopes}
let page = null; // AbortController of the page on screen
const blobUrls = new Map(); // digest -> object URL (digests are immutable)

// ---------- helpers ----------

function h(tag, attrs = {}, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === null || v === undefined || v === false) continue;
    if (k === "class") el.className = v;
    else if (k.startsWith("on")) el.addEventListener(k.slice(2), v);
    else if (k === "text") el.textContent = v;
    else el.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children.flat()) {
    if (c === null || c === undefined || c === false) continue;
    el.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return el;
}

const short = (d) => (d ? d.slice(0, 12) : "");

// What people call a character: the uploaded file's name, else its glTF
// scene's name, else its digest's start. Read once per digest.
const characterNames = new Map(); // digest -> Promise<{name, scene}>
function characterInfo(digest) {
  if (!characterNames.has(digest)) {
    characterNames.set(digest, json(`/v1/characters/${digest}`)
      .then((u) => ({ name: u.summary?.name || null, scene: u.summary?.scene || null }))
      .catch(() => {
        characterNames.delete(digest); // asked again next time
        return { name: null, scene: null };
      }));
  }
  return characterNames.get(digest);
}

// A character's label, filled in when its name arrives; the digest stays
// in the tooltip.
function characterLabel(digest) {
  const el = h("span", { class: "character", "data-character": digest, title: digest }, short(digest));
  characterInfo(digest).then(({ name, scene }) => {
    el.textContent = name || scene || short(digest);
    if (name && scene && scene !== name) el.append(" ", h("span", { class: "muted" }, scene));
    el.dataset.named = name || scene ? "yes" : "no";
  });
  return el;
}
const when = (ms) => (ms ? new Date(ms).toLocaleString() : "");
const ago = (ms) => {
  const s = Math.max(0, Math.round((Date.now() - ms) / 1000));
  return s < 60 ? `${s} s ago` : s < 3600 ? `${Math.round(s / 60)} min ago` : when(ms);
};
// An f32 value (stored as the f64 it widens to) in the fewest digits
// that give the same f32; any other value as it is.
const shortestF32 = (v) => {
  if (typeof v !== "number" || Number.isInteger(v) || Math.fround(v) !== v) return v;
  for (let p = 1; p < 9; p += 1) {
    const short = Number(v.toPrecision(p));
    if (Math.fround(short) === v) return short;
  }
  return v;
};
const fmt = (x, digits = 4) => (typeof x === "number" && isFinite(x) ? x.toFixed(digits) : "—");
// As the server checks: admin includes every scope, submit includes read.
const can = (scope) => !!me && (me.scopes.includes(scope) || me.scopes.includes("admin")
  || (scope === "read" && me.scopes.includes("submit")));
const finished = (state) => ["done", "failed", "cancelled"].includes(state);

class ApiError extends Error {
  constructor(status, problem) {
    super(problem.detail || problem.title || `HTTP ${status}`);
    this.status = status;
    this.problem = problem;
  }
}

// The sign-in page after the server refused `sent` (401), with its
// reason (expired, revoked); nothing when another token is in use by then
// (a request still under way from before a sign-out or a new sign-in).
async function refused(res, sent) {
  let problem = { title: "unauthorized" };
  try { problem = await res.json(); } catch (_) { /* not JSON */ }
  if (token === sent && sent !== null) {
    signOut(`The server did not accept this token${problem.detail ? `: ${problem.detail}` : "."}`);
  }
  return new ApiError(401, problem);
}

async function api(path, options = {}) {
  const sent = token;
  let res;
  try {
    res = await fetch(path, {
      ...options,
      headers: { authorization: `Bearer ${sent}`, ...(options.headers || {}) },
    });
  } catch (e) {
    connection(false);
    throw e;
  }
  connection(true);
  if (res.status === 401) throw await refused(res, sent);
  if (!res.ok) {
    let problem = {};
    try { problem = await res.json(); } catch (_) { /* not JSON */ }
    throw new ApiError(res.status, problem);
  }
  return res;
}
const json = async (path, options) => (await api(path, options)).json();

// An image by digest as an object URL: images need the token too.
async function imageUrl(path, digest) {
  if (!blobUrls.has(digest)) {
    const blob = await (await api(path)).blob();
    blobUrls.set(digest, URL.createObjectURL(blob));
  }
  return blobUrls.get(digest);
}

// The badge in the header: "live" while a page's event stream is open,
// "online" while the server answers a page that has none (the versions
// and compare pages), "offline" when a request could not reach it.
function connection(answered) {
  const live = document.getElementById("live");
  if (!answered) {
    live.textContent = "offline";
    live.classList.remove("on");
  } else if (!live.classList.contains("on")) {
    live.textContent = "online";
  }
}

// Server-sent events over fetch; reconnects until the page goes away or
// the token is refused.
async function events(path, signal, onEvent) {
  const live = document.getElementById("live");
  let wait = 500;
  while (!signal.aborted) {
    try {
      const sent = token;
      const res = await fetch(path, {
        headers: { authorization: `Bearer ${sent}`, accept: "text/event-stream" },
        signal,
      });
      // Refused (revoked, expired: the server also ends a stream whose
      // token is): stop listening; the sign-in page says why.
      if (res.status === 401) {
        await refused(res, sent);
        return;
      }
      if (!res.ok) throw new Error(`HTTP ${res.status}`);
      live.textContent = "live";
      live.classList.add("on");
      wait = 500;
      const reader = res.body.pipeThrough(new TextDecoderStream()).getReader();
      let buffer = "";
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        buffer += value;
        let end;
        while ((end = buffer.indexOf("\n\n")) >= 0) {
          const block = buffer.slice(0, end);
          buffer = buffer.slice(end + 2);
          let type = "message";
          const data = [];
          for (const line of block.split("\n")) {
            if (line.startsWith("event:")) type = line.slice(6).trim();
            else if (line.startsWith("data:")) data.push(line.slice(5).replace(/^ /, ""));
          }
          if (data.length) onEvent(type, data.join("\n"));
        }
      }
    } catch (e) {
      if (signal.aborted) return;
    }
    live.textContent = "reconnecting";
    live.classList.remove("on");
    await new Promise((r) => setTimeout(r, wait));
    wait = Math.min(wait * 2, 10000);
  }
}

// Calls `f` at most once per `ms`, the last call winning.
function throttle(f, ms) {
  let timer = null;
  return () => {
    if (timer) return;
    timer = setTimeout(() => { timer = null; f(); }, ms);
  };
}

// Widths are set through the CSSOM: the Content-Security-Policy forbids
// inline style attributes.
function progressBar(done, total, state) {
  const bar = h("div", { role: "progressbar", "aria-valuemin": 0, "aria-valuemax": 100 }, h("div"));
  setBar(bar, done, total, state);
  return bar;
}

// Units done of all, and the share as the bar shows it; work being done
// again (jobs leased again after a lost lease or a lost output) is counted
// once, and said.
const countText = (done, total, redo = 0) =>
  `${done}/${total} (${total > 0 ? Math.floor((100 * done) / total) : 0}%)` +
  (redo > 0 ? `, ${redo} being done again` : "");

function setBar(bar, done, total, state) {
  const pct = total > 0 ? Math.min(100, (100 * done) / total) : 0;
  bar.className = `bar ${state}`;
  bar.setAttribute("aria-valuenow", Math.round(pct));
  bar.dataset.done = done;
  bar.dataset.total = total;
  bar.firstChild.style.width = `${pct.toFixed(1)}%`;
}

const badge = (state) => h("span", { class: `badge ${state}`, "data-state": state }, state);

// A bake's state as its page shows it: a pause leases nothing new, and the
// jobs under way finish first, which the badge says.
function stateBadge(bake) {
  const running = bake.state === "paused" ? bake.jobs.filter((j) => j.state === "running").length : 0;
  return [badge(bake.state), running ? h("span", { class: "muted", id: "pausing" },
    ` ${running} running ${running === 1 ? "job finishes" : "jobs finish"} first`) : null];
}

// replaceChildren without the nulls that conditional parts leave; the
// tables in it (or around it) get their headers aligned.
function fill(el, ...nodes) {
  el.replaceChildren(...nodes.flat().filter((n) => n !== null && n !== undefined && n !== false));
  const around = el.closest("table");
  for (const table of around ? [around] : el.querySelectorAll("table")) alignHeads(table);
}

// A header sits over its numbers: right-aligned where its column's cells
// are (class num), so a figure is not read under the next column's name.
function alignHeads(table) {
  const rows = [...table.rows];
  const head = rows.find((r) => r.cells.length && [...r.cells].every((c) => c.tagName === "TH"));
  const body = rows.find((r) => [...r.cells].some((c) => c.tagName === "TD"));
  if (!head || !body) return;
  [...head.cells].forEach((th, i) => th.classList.toggle("num", !!body.cells[i]?.classList.contains("num")));
}

function show(...nodes) {
  fill(main, ...nodes);
}

function failure(e) {
  return h("div", { class: "error" }, e instanceof ApiError ? `${e.status}: ${e.message}` : String(e));
}

// ---------- sign-in ----------

function signOut(message) {
  localStorage.removeItem(TOKEN_KEY);
  token = null;
  me = null;
  // The page's requests and event streams stop with it: nothing redraws
  // the sign-in form under what someone is typing.
  if (page) page.abort();
  page = null;
  const live = document.getElementById("live");
  live.textContent = "offline";
  live.classList.remove("on");
  signIn(message);
}

function signIn(message) {
  document.getElementById("who").textContent = "";
  const input = h("input", { name: "token", autocomplete: "off", placeholder: "64 hex digits",
    "aria-label": "API token" });
  show(
    h("h1", {}, "Sign in"),
    message ? h("div", { class: "error" }, message) : null,
    h("form", { class: "login", onsubmit: (ev) => {
      ev.preventDefault();
      token = input.value.trim();
      localStorage.setItem(TOKEN_KEY, token);
      start();
    } },
      h("label", {}, "An API token (", h("code", {}, "aobake token create --scope read"),
        "; a read token sees the bakes, their reports and previews; the actions and the 3D viewer, which shows the character's mesh, need the submit scope):"),
      input,
      h("button", { type: "submit" }, "Sign in")),
  );
}

// ---------- pages ----------

async function bakesPage(signal) {
  const bakes = await json("/v1/bakes?limit=100");
  const rows = new Map();
  const tbody = h("tbody");
  for (const b of bakes) {
    const bar = progressBar(b.progress.done, b.progress.total, b.state);
    const state = h("td", {}, badge(b.state));
    const count = h("td", { class: "num mono" }, countText(b.progress.done, b.progress.total, b.progress.redo));
    rows.set(b.id, { bar, state, count });
    tbody.append(h("tr", { "data-bake": b.id },
      h("td", {}, h("a", { href: `#/bakes/${b.id}` }, `#${b.id}`)),
      h("td", {}, b.method),
      h("td", {}, characterLabel(b.character)),
      state,
      h("td", {}, bar),
      count,
      h("td", { class: "muted" }, when(b.created_at)),
      h("td", { class: "muted", "data-ended": b.finished_at ? "yes" : "no" }, when(b.finished_at) || "—"),
      h("td", { class: "num muted" }, b.finished_at ? duration((b.finished_at - b.created_at) / 1000) : "—")));
  }
  show(
    h("h1", {}, "Bakes"),
    bakes.length === 0
      ? h("p", { class: "muted" }, "No bakes yet: ", h("code", {}, "aobake submit CHARACTER.glb"), ".")
      : h("table", {},
        h("thead", {}, h("tr", {}, ...["Bake", "Method", "Character", "State", "Progress", "", "Created", "Ended", "Took"]
          .map((t) => h("th", {}, t)))),
        tbody),
  );
  const reload = throttle(() => { if (!signal.aborted) route(); }, 1000);
  events("/v1/events", signal, (type, data) => {
    if (type === "lagged") return reload();
    if (type !== "bake") return;
    const e = JSON.parse(data);
    const row = rows.get(e.id);
    if (!row) return reload(); // a new bake
    setBar(row.bar, e.done, e.total, e.state);
    fill(row.state, badge(e.state));
    row.count.textContent = countText(e.done, e.total, e.redo);
  });
}

function jobLabel(j) {
  const s = j.spec || {};
  if (j.kind === "sample") return `sample ${s.set} ${s.first}..${s.first + s.count}`;
  if (j.kind === "preview-truth") return `preview truth frames ${s.first}..${s.first + s.count}`;
  if (j.kind === "unseen") return `unseen fold ${s.fold}`;
  return j.kind;
}

// Job states as people read them: done, running, queued (blocked,
// available or waiting to retry), failed (out of attempts) or cancelled.
// As `aobake status` counts them: queued waits for a worker (a retry
// too), blocked for the jobs it needs.
const JOB_GROUP = {
  completed: "done", running: "running", blocked: "blocked", available: "queued",
  retryable: "queued", dead: "failed", cancelled: "cancelled",
};

// One row per stage (job kind, in graph order): how many jobs are in
// each state and how much of its work is done.
function stagesTable(jobs) {
  const stages = new Map();
  for (const j of jobs) {
    if (!stages.has(j.kind)) {
      stages.set(j.kind, { jobs: 0, done: 0, running: 0, queued: 0, blocked: 0, failed: 0, cancelled: 0, work: 0, worked: 0 });
    }
    const st = stages.get(j.kind);
    st.jobs += 1;
    st[JOB_GROUP[j.state] || "queued"] += 1;
    st.work += j.work;
    st.worked += j.state === "completed" ? j.work : j.progress;
  }
  return h("table", { id: "stages" },
    h("thead", {}, h("tr", {}, ...["Stage", "Jobs", "Done", "Running", "Queued", "Blocked", "Failed", "Cancelled", "Work"]
      .map((t) => h("th", {}, t)))),
    h("tbody", {}, ...[...stages].map(([kind, st]) => h("tr", { "data-stage": kind },
      h("td", {}, kind),
      h("td", { class: "num" }, st.jobs),
      h("td", { class: "num", "data-count": "done" }, st.done),
      h("td", { class: "num", "data-count": "running" }, st.running),
      h("td", { class: "num", "data-count": "queued" }, st.queued),
      h("td", { class: "num", "data-count": "blocked" }, st.blocked),
      h("td", { class: st.failed ? "num error" : "num", "data-count": "failed" }, st.failed),
      h("td", { class: "num", "data-count": "cancelled" }, st.cancelled),
      h("td", { class: "num" }, `${st.worked}/${st.work}`)))));
}

// Seconds as people say them.
function duration(s) {
  if (!Number.isFinite(s)) return "—";
  if (s < 60) return `${Math.max(1, Math.round(s))} s`;
  if (s < 3600) return `${Math.round(s / 60)} min`;
  return `${(s / 3600).toFixed(1)} h`;
}

// The time left from the bake's jobs, each stage (job kind) at its own
// pace: its finished jobs' seconds per unit of work (lease to completion),
// the work left spread over the jobs running side by side. A kind with no
// finished job yet has no pace: the estimate is then a floor, and says
// which kinds it lacks. aobake-api's progress::time_left is the same in
// Rust (what `aobake submit --wait` shows).
function timeLeft(bake, now = Date.now()) {
  if (finished(bake.state) || bake.state === "queued") return "";
  if (bake.state === "paused") return "paused";
  const jobs = bake.jobs || [];
  const pace = new Map(); // kind → [seconds, units]
  for (const j of jobs) {
    if (j.state !== "completed" || j.started_at == null || j.finished_at == null || j.work <= 0) continue;
    const p = pace.get(j.kind) || [0, 0];
    p[0] += Math.max(0, j.finished_at - j.started_at) / 1000;
    p[1] += j.work;
    pace.set(j.kind, p);
  }
  let left = 0;
  let running = 0;
  let any = false;
  const unknown = [];
  for (const j of jobs) {
    if (!["blocked", "available", "retryable", "running"].includes(j.state)) continue;
    any = true;
    const p = pace.get(j.kind);
    if (!p || p[1] <= 0) {
      if (!unknown.includes(j.kind)) unknown.push(j.kind);
      continue;
    }
    const whole = (j.work * p[0]) / p[1];
    if (j.state === "running" && j.started_at != null) {
      running += 1;
      left += Math.max(0, whole - Math.max(0, now - j.started_at) / 1000);
    } else left += whole;
  }
  if (!any) return "";
  const at = left / Math.max(1, running);
  return unknown.length
    ? `at least ${duration(at)} left (no ${unknown.join(" or ")} job has finished yet)`
    : `about ${duration(at)} left (each stage at the pace of its finished jobs)`;
}

function jobsTable(jobs, id = "jobs") {
  return h("table", { id },
    h("thead", {}, h("tr", {}, ...["#", "Job", "State", "Attempts", "Worker", "Checkpoint", "Progress", "Needs", "Error"]
      .map((t) => h("th", {}, t)))),
    h("tbody", {}, ...jobs.map((j) => h("tr", { "data-job": j.index },
      h("td", { class: "num" }, j.index),
      h("td", {}, jobLabel(j)),
      h("td", {}, badge(j.state)),
      h("td", { class: "num" }, `${j.attempts}/${j.max_attempts}`),
      h("td", { class: "mono" }, j.worker || ""),
      h("td", { class: "mono" }, j.checkpoint ? `${j.checkpoint.step} ${j.checkpoint.cursor}` : ""),
      h("td", { class: "num" }, `${j.state === "completed" ? j.work : j.progress}/${j.work}`),
      h("td", { class: "muted" }, j.deps.length > 6 ? `${j.deps.length} jobs` : j.deps.join(", ")),
      h("td", { class: "muted" }, j.error || "")))));
}

// A wide image shown at its own size in a scrolling frame (its text is
// small when fitted to the page), with a button to fit it instead.
function zoomable(url, alt, caption) {
  const figure = h("figure", { class: "wide zoom", "data-zoom": "actual" });
  const toggle = h("button", { type: "button", class: "small", "data-action": "zoom", onclick: () => {
    const fit = figure.dataset.zoom === "actual";
    figure.dataset.zoom = fit ? "fit" : "actual";
    toggle.textContent = fit ? "Actual size" : "Fit to width";
  } }, "Fit to width");
  figure.append(h("div", { class: "scroll" }, h("img", { src: url, alt })), h("figcaption", {}, caption, " ", toggle));
  return figure;
}

function cubemapReportSection(report, plotUrl) {
  const ev = report.evaluation;
  const l = report.layout;
  const err = (e) => [fmt(e.mean.rmse), fmt(e.mean.too_dark_mse, 6), fmt(e.mean.too_bright_mse, 6)];
  return h("section", { id: "report" },
    h("h2", {}, "Quality"),
    h("p", { class: "muted" },
      `Clip ${report.clip}: ${l.resolution}² texels, ${l.spheroid.shells} shells, ${l.times} time samples. `,
      `Ground truth at ${ev.times.length} random times: ${ev.space_points} points in space and `,
      `${ev.ground_points} on the ground each, ${ev.rays_per_point} rays per point `,
      `(${ev.space_hidden} inside the mesh and ${ev.ground_hidden} under the character left out); `,
      `its own noise RMSE ${fmt(ev.ground_truth_noise_rmse)}.`),
    h("table", {},
      h("thead", {}, h("tr", {}, ...["Variant", "Bytes", "Space RMSE", "too dark", "too bright",
        "Ground RMSE", "too dark", "too bright"].map((t) => h("th", {}, t)))),
      h("tbody", {}, ...ev.variants.map((v) => h("tr", { title: v.description },
        h("td", {}, v.name),
        h("td", { class: "num" }, v.bytes),
        ...[...err(v.space), ...err(v.ground)].map((x) => h("td", { class: "num" }, x)))))),
    h("p", { class: "muted" }, `Asset ${report.sizes.asset_bytes} bytes.`),
    plotUrl ? zoomable(plotUrl, "time × distance charts",
      "Time × distance at the worst, a 90th-percentile and the median texel: input, then each encoding decoded and its error") : null);
}

function gridReportSection(report, plotUrl) {
  const ev = report.evaluation;
  const err = (e) => [fmt(e.mean.rmse), fmt(e.mean.too_dark_mse, 6), fmt(e.mean.too_bright_mse, 6)];
  return h("section", { id: "report" },
    h("h2", {}, "Quality"),
    h("table", {},
      h("thead", {}, h("tr", {}, ...["Part", "Vertices", "Grid", "V_M", "Inside cells", "Bytes",
        "Bake (s)"].map((t) => h("th", {}, t)))),
      h("tbody", {}, ...report.parts.map((p) => h("tr", {},
        h("td", {}, p.name),
        h("td", { class: "num" }, p.vertices),
        h("td", { class: "num" }, `${p.resolution}³`),
        h("td", { class: "num" }, fmt(p.boundary_max)),
        h("td", { class: "num" }, p.inside_cells),
        h("td", { class: "num" }, p.bytes[report.params.grid.cones ? 0 : 1]),
        h("td", { class: "num" }, fmt(p.bake_s, 2)))))),
    h("p", { class: "muted" },
      `Ground truth at ${ev.frames.length} random clip frames: ${ev.vertices} vertices of parts and `,
      `${ev.ground_points} ground points (${ev.ground_hidden} under a contact left out), `,
      `${ev.rays_per_point} rays each; its own noise RMSE ${fmt(ev.noise_rmse_vertices)} (vertices), `,
      `${fmt(ev.noise_rmse_ground)} (ground). Run time ${fmt(ev.lookup_ns_per_receiver, 0)} ns per receiver on one CPU thread.`),
    h("table", {},
      h("thead", {}, h("tr", {}, ...["Variant", "Bytes", "Vertices RMSE", "too dark", "too bright",
        "Ground RMSE", "too dark", "too bright"].map((t) => h("th", {}, t)))),
      h("tbody", {}, ...ev.variants.map((v) => h("tr", { title: v.description },
        h("td", {}, v.name),
        h("td", { class: "num" }, v.bytes),
        ...[...err(v.vertices), ...err(v.ground)].map((x) => h("td", { class: "num" }, x)))))),
    h("p", { class: "muted" }, `Asset ${report.sizes.asset_bytes} bytes.`),
    plotUrl ? h("figure", { class: "wide" }, h("img", { src: plotUrl, alt: "grid slices" }),
      h("figcaption", {}, "Every part's grid through its middle (x, y and z constant), dark where occluded")) : null);
}

// The reference rows a fit can choose (`reference = cv`).
const ROWS = {
  mixed: "random poses and clip frames",
  perturbed: "clip frames and perturbed frames",
  all: "all three",
};

function reportSection(report, plotUrl) {
  if (report.layout) return cubemapReportSection(report, plotUrl);
  if (report.parts) return gridReportSection(report, plotUrl);
  // A family this page has no figures for: its plot and its evaluation.
  if (!report.fit) {
    return h("section", { id: "report" },
      h("h2", {}, "Quality"),
      plotUrl ? h("figure", { class: "wide" }, h("img", { src: plotUrl, alt: "report plot" })) : null,
      h("pre", { class: "mono" }, JSON.stringify(report.evaluation ?? report, null, 2)));
  }
  const ev = report.evaluation;
  const unseen = ev.unseen_clips;
  const reference = report.fit?.reference;
  const basis = report.fit?.basis;
  const basisCv = report.fit?.basis_cv;
  const rows = [
    // The worst left-out clip first: what a studio's next clip risks.
    ...(unseen ? worstFirst(unseen.folds).map((f) => [`unseen clip ${f.clip} (refitted without it)`, f.errors]) : []),
    ["frames of the training clips, fresh rays", ev.training_clip_frames || ev.clip_frames],
    ["held-out random poses", ev.random_poses],
  ];
  return h("section", { id: "report" },
    h("h2", {}, "Quality"),
    h("table", {},
      h("thead", {}, h("tr", {}, ...["Poses", "Frames", "Model MAE", "Model RMSE", "Model PSNR",
        "Static MAE", "Static RMSE", "Static PSNR", "Gain"].map((t) => h("th", {}, t)))),
      h("tbody", {}, ...rows.map(([name, c]) => h("tr", {},
        h("td", {}, name),
        h("td", { class: "num" }, c.model.frames),
        h("td", { class: "num" }, fmt(c.model.mean.mae)),
        h("td", { class: "num" }, fmt(c.model.mean.rmse)),
        h("td", { class: "num" }, `${fmt(c.model.mean.psnr_db, 2)} dB`),
        h("td", { class: "num" }, fmt(c.baseline.mean.mae)),
        h("td", { class: "num" }, fmt(c.baseline.mean.rmse)),
        h("td", { class: "num" }, `${fmt(c.baseline.mean.psnr_db, 2)} dB`),
        h("td", { class: "num" }, `${c.psnr_gain_db >= 0 ? "+" : ""}${fmt(c.psnr_gain_db, 2)} dB`))))),
    unseen ? h("p", { id: "unseen" },
      `Unseen clips (leave one clip out, ${unseen.folds.length} folds): ${fmt(unseen.model_psnr_db, 2)} dB against `,
      `${fmt(unseen.baseline_psnr_db, 2)} dB, ${unseen.mean_psnr_gain_db >= 0 ? "+" : ""}${fmt(unseen.mean_psnr_gain_db, 2)} dB `,
      `on average (worst fold ${unseen.min_psnr_gain_db >= 0 ? "+" : ""}${fmt(unseen.min_psnr_gain_db, 2)} dB). `,
      "The static average is the mean over training clip frames.") : null,
    reference ? h("p", { id: "reference" },
      `Reference poses: ${ROWS[reference.rows] || reference.rows}, chosen by cross-validation over clips `,
      `(mean PSNR on left-out clips: ${reference.scores.map(([r, db]) => `${ROWS[r] || r} ${fmt(db, 2)} dB`).join(", ")}).`) : null,
    basis && basisCv ? h("p", { id: "basis" },
      `Eigen-AO basis: ${basis.rank} rows`,
      basis.threshold > 0 ? `, entries under 1/${Math.round(1 / basis.threshold)} dropped` : "",
      ` (${fmt(basis.multiply_adds, 1)} multiply-adds a vertex), the cheapest of ${basisCv.candidates.length} `,
      `candidates within ${basisCv.tolerance_db} dB of the best on left-out clips (cross-validation over clips: `,
      `${fmt(Math.max(...basisCv.candidates.map((c) => c.psnr_db)), 2)} dB at best).`) : null,
    h("p", { class: "muted" },
      `Ground truth's own noise: RMSE ${fmt(report.ground_truth_noise?.rmse)}. `,
      `Asset ${report.sizes.asset_bytes} bytes; ${fmt(ev.multiply_adds_per_vertex, 1)} multiply-adds per vertex.`),
    plotUrl ? h("figure", { class: "wide" }, h("img", { src: plotUrl, alt: "PSNR per frame" }),
      h("figcaption", {}, "PSNR per frame of the training clips (fresh rays), model against the static average; the unseen-clip folds are in the table")) : null);
}

function previewFigure(p, url) {
  const times = p.kind === "animation"
    ? `${p.times.length} frames`
    : `t = ${p.times.map((t) => t.toFixed(2)).join(", ")} s`;
  const what = p.kind === "unseen"
    ? `still of ${p.clip}, drawn with the model refitted without it`
    : `${p.kind}${p.clip ? ` of ${p.clip}` : ""}`;
  return h("figure", { class: p.kind === "animation" ? "preview" : "wide preview", "data-kind": p.kind },
    h("img", { src: url, alt: `${p.kind} ${p.name}`, width: p.width, height: p.height }),
    h("figcaption", {}, `${what}, ${times}; `,
      `${fmt(p.frame_ms, 1)} ms per panel on ${p.adapter}`),
    p.screen_space ? screenSpaceTable(p.screen_space) : null);
}

// What the bake found, in a few sentences a producer reads at the top:
// its gain over the static average on clips it never saw and on training
// frames, and per pixel against screen-space AO, with the per-vertex
// floor named when it is what holds the model back.
// Unseen-clip folds ordered by their gain over the static average, the
// worst first (a stable sort: ties keep the report's order).
const worstFirst = (folds) =>
  [...folds].sort((a, b) => a.errors.psnr_gain_db - b.errors.psnr_gain_db);

function headlineOf(report, pixels) {
  const db = (x) => `${x >= 0 ? "+" : ""}${fmt(x, 1)} dB`;
  const out = [];
  const ev = report.evaluation;
  const unseen = ev?.unseen_clips;
  const seen = ev?.training_clip_frames;
  if (unseen && seen) {
    const worst = worstFirst(unseen.folds)[0];
    out.push(h("span", { id: "headline-gain" },
      `Over the static average: ${db(worst.errors.psnr_gain_db)} on ${worst.clip}, the clip it never saw that it does worst on; `,
      `${db(unseen.mean_psnr_gain_db)} over all ${unseen.folds.length} it never saw, ${db(seen.psnr_gain_db)} on frames of its training clips. `));
  } else if (seen) {
    out.push(h("span", { id: "headline-gain" },
      `Over the static average: ${db(seen.psnr_gain_db)} on frames of its training clips. `));
  }
  const still = pixels?.stills?.[0];
  if (still) {
    const better = still.model < still.gtao;
    out.push(h("span", { id: "headline-pixels" },
      `Per pixel on the character, the bake is ${fmt(still.model, 3)} from ray-traced AO; screen-space AO `,
      `(GTAO, what an engine computes without a bake) is ${fmt(still.gtao, 3)}: the bake is `,
      better ? "closer. " : "further. "));
    // A per-vertex model at its floor: the mesh, not the fit, is the limit.
    if (!better && still.texel_floor == null && still.per_vertex_floor >= 0.9 * still.model) {
      out.push(h("span", { id: "headline-floor" },
        `The per-vertex floor (the exact AO at the vertices, interpolated) is ${fmt(still.per_vertex_floor, 3)}: `,
        "no per-vertex bake of this mesh can do better; texel-linear stores AO per texel of an atlas. "));
    }
  }
  const folds = pixels?.unseen;
  if (folds?.length && pixels.unseen_mean_gain_db != null) {
    out.push(h("span", { id: "headline-unseen" },
      `On clips it never saw, per pixel: ${db(pixels.unseen_mean_gain_db)} over the static average `,
      `(worst ${db(pixels.unseen_worst_gain_db)}). `));
  }
  return out;
}

// The stills judged per pixel, pooled per clip: the bake's model on its
// preview clip and each unseen-clip fold's model on the clip it left out,
// beside the static average, the floors and GTAO.
function pixelTable(s) {
  const opt = (x) => (x === undefined || x === null ? "—" : fmt(x));
  const gain = (g) => (g === undefined || g === null ? "—" : `${g >= 0 ? "+" : ""}${fmt(g, 2)} dB`);
  const rows = [
    ...s.stills.map((e) => [e, e.trained ? "the bake's (trained on it)" : "the bake's (held out of training)"]),
    ...s.unseen.map((e) => [e, "refitted without it"]),
  ];
  return h("div", { id: "pixels" },
    h("table", {},
      h("caption", {}, "Per pixel on the character: RMSE against ray-traced AO, pooled over each clip's stills"),
      h("thead", {}, h("tr", {}, ...["Clip", "Model", "Stills", "Model RMSE", "Static average", "Gain",
        "Texel floor", "Per-vertex floor", "GTAO", "Model / GTAO"].map((t) => h("th", {}, t)))),
      h("tbody", {}, ...rows.map(([e, whose]) => h("tr", {},
        h("td", {}, e.clip),
        h("td", {}, whose),
        h("td", { class: "num" }, e.stills),
        h("td", { class: "num" }, fmt(e.model)),
        h("td", { class: "num" }, opt(e.static_average)),
        h("td", { class: "num" }, gain(e.gain_db)),
        h("td", { class: "num" }, opt(e.texel_floor)),
        h("td", { class: "num" }, fmt(e.per_vertex_floor)),
        h("td", { class: "num" }, fmt(e.gtao)),
        h("td", { class: "num" }, fmt(e.model / e.gtao, 2)))))),
    h("p", { class: "muted" },
      s.unseen_mean_gain_db !== undefined
        ? `Unseen clips per pixel: ${gain(s.unseen_mean_gain_db)} over the static average on average, worst clip ${gain(s.unseen_worst_gain_db)}. `
        : "",
      `Worst model / GTAO: ${fmt(s.worst_gtao_ratio, 2)} (below 1, the bake beats screen-space AO on every clip judged).`));
}

// The footnote of surfaces whose model is not judged: one sentence per
// reason, naming every surface it holds for (not the same one twice).
function notJudged(unjudged) {
  const byWhy = new Map();
  for (const [name, why] of unjudged) {
    if (!byWhy.has(why)) byWhy.set(why, []);
    byWhy.get(why).push(name);
  }
  return [...byWhy].map(([why, names]) => `* The baked model on the ${names.join(" and the ")} is not judged: ${why}. `);
}

// A still's screen-space baseline (GTAO, its third panel) beside the
// model: RMSE against per-pixel ray-traced AO, and each one's cost.
function screenSpaceTable(s) {
  // Where the model is not judged (a surface its method does not shade),
  // the dash says why in a note under the table, not only in a tooltip.
  const unjudged = [];
  const row = (name, e) => {
    if (!e) return null;
    let model;
    if (e.model) model = h("td", { class: "num" }, fmt(e.model.rmse));
    else {
      if (e.model_not_judged) unjudged.push([name, e.model_not_judged]);
      model = h("td", { class: "num", title: e.model_not_judged || "" }, e.model_not_judged ? "—*" : "—");
    }
    return h("tr", {},
      h("td", {}, `${name} (${e.pixels} px)`),
      model,
      statics ? h("td", { class: "num" }, e.texel_models?.length ? fmt(e.texel_models[0].rmse) : "—") : null,
      h("td", { class: "num" }, fmt(e.gtao.rmse)),
      h("td", { class: "num" }, fmt(e.per_vertex_truth.rmse)),
      texels ? h("td", { class: "num" }, e.texel_truth ? fmt(e.texel_truth.rmse) : "—") : null);
  };
  // A texel model's still: its texel floor; an unseen fold's: its static
  // average too.
  const texels = !!s.atlas;
  const statics = !!s.character?.texel_models?.length;
  const rows = [row("character", s.character), row("ground", s.ground)];
  return h("div", { class: "screen-space" },
    h("table", { class: "screen-space-errors" },
      h("caption", {}, "RMSE against per-pixel ray-traced AO"),
      h("tr", {}, h("th", {}, "surface"), h("th", {}, "baked model"),
        statics ? h("th", {}, "static average") : null, h("th", {}, "GTAO"), h("th", {}, "per-vertex truth"),
        texels ? h("th", {}, "texel truth") : null),
      rows),
    unjudged.length ? h("p", { class: "muted not-judged" }, notJudged(unjudged)) : null,
    h("p", { class: "muted" },
      `Per frame on this adapter: GTAO ${fmt(s.gtao_ms, 2)} ms (${s.fetches_per_pixel} texel reads per pixel, radius ${fmt(s.gtao.radius, 3)}), `,
      `the model's evaluation ${fmt(s.model_ms, 2)} ms.`));
}

async function bakePage(signal, id) {
  let bake = await json(`/v1/bakes/${id}`);
  const bar = progressBar(bake.progress.done, bake.progress.total, bake.state);
  const state = h("span", { id: "state" }, ...stateBadge(bake));
  const count = h("span", { class: "mono", id: "count" }, countText(bake.progress.done, bake.progress.total, bake.progress.redo));
  // Jobs: a summary by stage with the time left, the running and failed
  // jobs, and every job folded away (a vertex bake has hundreds).
  const stages = h("div");
  const eta = h("p", { id: "eta", class: "muted" });
  const active = h("div");
  const allJobs = h("div");
  const foldTitle = h("summary");
  const folded = h("details", { id: "all-jobs" }, foldTitle, allJobs);
  const drawJobs = () => {
    fill(stages, stagesTable(bake.jobs));
    const shown = bake.jobs.filter((j) => j.state === "running" || j.state === "dead" || j.state === "retryable");
    shown.sort((a, b) => (a.state === "running") - (b.state === "running") || a.index - b.index);
    fill(active, shown.length
      ? jobsTable(shown, "active")
      : h("p", { class: "muted", id: "active" }, "No job is running or failing."));
    fill(allJobs, jobsTable(bake.jobs));
    foldTitle.textContent = `All ${bake.jobs.length} jobs`;
    eta.textContent = timeLeft(bake);
  };
  drawJobs();
  // A queued bake's place: the bakes with work that run before it (higher
  // priority, or as high and older; the server leases in that order).
  const queue = h("p", { id: "queue", class: "muted" });
  const drawQueue = async () => {
    if (bake.state !== "queued") return fill(queue);
    const all = await json("/v1/bakes?limit=1000");
    const ahead = all.filter((b) => b.id !== bake.id && (b.state === "queued" || b.state === "running")
      && (b.priority > bake.priority || (b.priority === bake.priority && b.id < bake.id))).length;
    queue.textContent = ahead === 0
      ? "Queued: it runs next when a worker is free."
      : `Queued behind ${ahead} ${ahead === 1 ? "bake" : "bakes"} (higher priority, or as high and older).`;
  };
  drawQueue().catch(() => {});
  const jobs = h("div", {}, stages, queue, eta, h("h3", {}, "Running and failed"), active, folded);
  const results = h("div", { id: "results" });
  const headline = h("p", { id: "headline" });
  // The 3D viewer, once the bake has its asset: it shows the character's
  // mesh, which needs the submit scope as the uploads do.
  const viewerSlot = h("div");
  let viewerShown = false;
  const drawViewer = () => {
    if (viewerShown || !bake.asset) return;
    viewerShown = true;
    fill(viewerSlot, can("submit")
      ? viewerSection(id, { api, h })
      : h("section", { id: "viewer" }, h("h2", {}, "Viewer"),
        h("p", { class: "note", id: "viewer-status" },
          `The viewer shows the character's mesh: your token “${me.name}” can read only, and the mesh needs the submit scope.`)));
  };
  const status = h("div");
  let loadedResults = false;

  // Cancel asks first: a click that slipped would stop a long bake.
  const confirmCancel = () => confirm(`Cancel bake #${id}? Its running jobs stop at their next checkpoint `
    + "and no job of it is leased again; Retry takes it up again, keeping what finished.");
  const act = (action) => async () => {
    if (action === "cancel" && !confirmCancel()) return;
    fill(status);
    try {
      await api(`/v1/bakes/${id}/${action}`, { method: "POST" });
      await refresh();
    } catch (e) {
      fill(status, failure(e));
    }
  };
  const mayAct = can("submit");
  const button = (label, action) => h("button", {
    "data-action": action, disabled: true,
    title: mayAct ? null : "needs a token with the submit scope", onclick: act(action),
  }, label);
  const download = async () => {
    const res = await api(`/v1/assets/${bake.asset}`);
    const a = h("a", { href: URL.createObjectURL(await res.blob()),
      download: `bake-${id}-${bake.method}.aobake` });
    document.body.append(a);
    a.click();
    a.remove();
  };
  // The buttons are made once and only their state changes: a button
  // replaced under the pointer between press and release loses the click.
  const buttons = {
    cancel: button("Cancel", "cancel"),
    pause: button("Pause", "pause"),
    resume: button("Resume", "resume"),
    retry: button("Retry", "retry"),
    download: h("button", { "data-action": "download", disabled: true, onclick: download }, "Download asset"),
  };
  // Priority: higher runs first (PATCH /v1/bakes/{id}).
  const priority = h("input", { type: "number", step: 1, id: "priority", "aria-label": "Priority (higher runs first)" });
  priority.value = bake.priority;
  const setPriority = async (ev) => {
    ev.preventDefault();
    fill(status);
    try {
      await api(`/v1/bakes/${id}`, { method: "PATCH", headers: { "content-type": "application/json" },
        body: JSON.stringify({ priority: Math.trunc(Number(priority.value)) }) });
      await refresh();
    } catch (e) {
      fill(status, failure(e));
    }
  };
  const prioritySet = h("button", { type: "submit", "data-action": "priority", disabled: true,
    title: mayAct ? "higher runs first" : "needs a token with the submit scope" }, "Set priority");
  const actions = h("div", { class: "actions" }, Object.values(buttons),
    h("form", { class: "priority", onsubmit: setPriority }, priority, prioritySet),
    mayAct ? null : h("span", { class: "note", id: "read-only" },
      `Your token “${me.name}” can read only: cancel, pause, resume, retry and the priority need the submit scope.`));
  const drawActions = () => {
    const s = bake.state;
    priority.disabled = prioritySet.disabled = !mayAct || finished(s);
    if (document.activeElement !== priority) priority.value = bake.priority;
    buttons.cancel.disabled = !mayAct || finished(s);
    buttons.pause.disabled = !mayAct || !(s === "queued" || s === "running");
    buttons.resume.disabled = !mayAct || s !== "paused";
    buttons.retry.disabled = !mayAct || !(s === "failed" || s === "cancelled");
    buttons.download.disabled = !bake.asset;
  };

  async function loadResults() {
    if (loadedResults || !bake.report) return;
    loadedResults = true;
    try {
      const report = await json(`/v1/bakes/${id}/report`);
      const plot = bake.plot ? await imageUrl(`/v1/assets/${bake.plot}`, bake.plot) : null;
      const list = await json(`/v1/bakes/${id}/previews`);
      const figures = [];
      for (const p of list.previews) {
        figures.push(previewFigure(p, await imageUrl(`/v1/previews/${p.digest}`, p.digest)));
      }
      fill(headline, ...headlineOf(report, list.pixels));
      fill(results,
        h("h2", {}, "Previews"),
        list.pixels ? pixelTable(list.pixels) : null,
        figures.length
          ? h("div", { class: "grid", id: "previews" }, figures)
          : h("p", { class: "muted", id: "no-previews" }, list.unavailable
            ? `No previews: ${list.unavailable}`
            : list.state ? `The preview job is ${list.state}.` : "No previews."),
        reportSection(report, plot));
      if (list.state && list.state !== "completed") loadedResults = false;
    } catch (e) {
      loadedResults = false;
      fill(results, failure(e));
    }
  }

  async function refresh() {
    bake = await json(`/v1/bakes/${id}`);
    setBar(bar, bake.progress.done, bake.progress.total, bake.state);
    fill(state, ...stateBadge(bake));
    count.textContent = countText(bake.progress.done, bake.progress.total, bake.progress.redo);
    drawJobs();
    drawQueue().catch(() => {});
    drawDetails();
    drawActions();
    drawViewer();
    loadResults();
  }

  const details = h("dl", { class: "kv" });
  const drawDetails = () => fill(details,
    h("dt", {}, "Bake key"), h("dd", { class: "mono" }, bake.key),
    h("dt", {}, "Character"), h("dd", {}, characterLabel(bake.character), " ",
      h("span", { class: "mono muted" }, short(bake.character)), " ",
      h("a", { href: `#/versions/${bake.character}/${bake.method}` }, "versions")),
    h("dt", {}, "Clips"), h("dd", { class: "mono" }, bake.clips.map(short).join(", ") || "in the character file"),
    h("dt", {}, "Created"), h("dd", {}, when(bake.created_at)),
    h("dt", {}, "Finished"), h("dd", {}, when(bake.finished_at) || "—"),
    bake.error ? h("dt", {}, "Error") : null, bake.error ? h("dd", { class: "error" }, bake.error) : null);
  drawDetails();
  drawActions();
  drawViewer();
  show(
    h("h1", {}, `Bake #${id} `, characterLabel(bake.character), " ", h("span", { class: "muted" }, bake.method), " ", state),
    h("div", { class: "actions" }, bar, count),
    headline,
    actions,
    status,
    details,
    viewerSlot,
    results,
    h("h2", {}, "Jobs"),
    jobs,
    h("h2", {}, "Parameters"),
    // f32 parameters as people wrote them (0.1, not 0.10000000149011612).
    h("pre", { class: "mono", id: "params" }, JSON.stringify(bake.params, (_, v) => shortestF32(v), 2)),
  );
  loadResults();
  const later = throttle(() => { if (!signal.aborted) refresh().catch(() => {}); }, 400);
  events(`/v1/bakes/${id}/events`, signal, (type, data) => {
    if (type !== "bake") return;
    const e = JSON.parse(data);
    setBar(bar, e.done, e.total, e.state);
    fill(state, badge(e.state));
    count.textContent = countText(e.done, e.total, e.redo);
    later();
  });
}

async function workersPage(signal) {
  const tbody = h("tbody");
  const draw = async () => {
    const workers = await json("/v1/workers");
    fill(tbody, ...workers.map((w) => h("tr", { "data-worker": w.id },
      h("td", { class: "mono" }, w.id),
      h("td", {}, badge(w.state)),
      h("td", {}, w.job_id == null ? ""
        : h("a", { href: `#/bakes/${w.bake_id}` }, `bake #${w.bake_id}`, h("span", { class: "muted" }, ` (job ${w.job_id})`))),
      h("td", { class: "tracer" }, w.tracer ?? "cpu"),
      h("td", { "data-seen": w.last_seen }, ago(w.last_seen)),
      h("td", { class: "muted" }, when(w.started_at)))));
  };
  await draw();
  show(h("h1", {}, "Workers"),
    h("table", {}, h("thead", {}, h("tr", {}, ...["Worker", "State", "Job", "Tracer", "Last heartbeat", "Started"]
      .map((t) => h("th", {}, t)))), tbody));
  // Relative times tick locally; the list is re-read when a bake changes
  // and every 10 s (idle workers poll without any bake changing).
  const later = throttle(() => { if (!signal.aborted) draw().catch(() => {}); }, 1000);
  const tick = setInterval(() => {
    for (const td of tbody.querySelectorAll("[data-seen]")) td.textContent = ago(Number(td.dataset.seen));
  }, 1000);
  const reread = setInterval(later, 10000);
  signal.addEventListener("abort", () => { clearInterval(tick); clearInterval(reread); });
  events("/v1/events", signal, () => later());
}

async function versionsPage(signal, character, method) {
  if (!character) {
    const bakes = await json("/v1/bakes?limit=100");
    const groups = new Map();
    for (const b of bakes) {
      const k = `${b.character}/${b.method}`;
      if (!groups.has(k)) groups.set(k, { character: b.character, method: b.method, count: 0 });
      groups.get(k).count += 1;
    }
    show(h("h1", {}, "Versions"),
      h("table", {}, h("thead", {}, h("tr", {}, ...["Character", "Method", "Bakes"].map((t) => h("th", {}, t)))),
        h("tbody", {}, ...[...groups.values()].map((g) => h("tr", {},
          h("td", {}, h("a", { href: `#/versions/${g.character}/${g.method}` }, characterLabel(g.character))),
          h("td", {}, g.method),
          h("td", { class: "num" }, g.count))))));
    return;
  }
  const list = await json(`/v1/characters/${character}/bakes?method=${encodeURIComponent(method)}`);
  show(h("h1", {}, "Versions of ", characterLabel(character), ` (${method})`),
    h("table", {}, h("thead", {}, h("tr", {}, ...["Version", "Bake", "State", "Bake key", "Asset", "Finished", "Compare"]
      .map((t) => h("th", {}, t)))),
      h("tbody", {}, ...list.map((b, i) => h("tr", { "data-bake": b.id },
        h("td", { class: "num" }, list.length - i),
        h("td", {}, h("a", { href: `#/bakes/${b.id}` }, `#${b.id}`)),
        h("td", {}, badge(b.state)),
        h("td", { class: "mono" }, short(b.key)),
        h("td", { class: "mono" }, short(b.asset) || "—"),
        h("td", {}, when(b.finished_at)),
        // Against the version before it (the list is newest first).
        h("td", {}, list[i + 1] ? h("a", { class: "compare", href: `#/compare/${list[i + 1].id}/${b.id}` },
          `against #${list[i + 1].id}`) : ""))))));
}

// ---------- comparing two bakes ----------

// A bake's headline figures from its report, by family: each with whether
// a larger value is better ("up") or worse ("down").
function headline(report) {
  const rows = [];
  const add = (label, value, better, digits = 4, unit = "") => {
    if (typeof value === "number" && isFinite(value)) rows.push({ label, value, better, digits, unit });
  };
  const ev = report?.evaluation;
  if (!ev) return rows;
  if (report.fit) {
    const u = ev.unseen_clips;
    if (u) {
      add("Unseen clips: model PSNR", u.model_psnr_db, "up", 2, " dB");
      add("Unseen clips: gain over the static average", u.mean_psnr_gain_db, "up", 2, " dB");
      add("Unseen clips: worst fold's gain", u.min_psnr_gain_db, "up", 2, " dB");
    }
    for (const [name, c] of [["Training clip frames", ev.training_clip_frames || ev.clip_frames],
      ["Held-out random poses", ev.random_poses]]) {
      if (!c) continue;
      add(`${name}: model PSNR`, c.model?.mean?.psnr_db, "up", 2, " dB");
      add(`${name}: model RMSE`, c.model?.mean?.rmse, "down");
    }
    add("Multiply-adds per vertex", ev.multiply_adds_per_vertex, "down", 1);
  } else if (report.layout || report.parts) {
    const receivers = report.layout ? "space" : "vertices";
    for (const v of ev.variants || []) {
      add(`${v.name}: ${receivers} RMSE`, v[receivers]?.mean?.rmse, "down");
      add(`${v.name}: ground RMSE`, v.ground?.mean?.rmse, "down");
    }
  }
  add("Asset bytes", report.sizes?.asset_bytes, "down", 0);
  return rows;
}

// Every parameter as `path → value`, f32 values as people wrote them.
function flatParams(params, prefix = "", out = new Map()) {
  for (const [k, v] of Object.entries(params || {})) {
    const path = prefix ? `${prefix}.${k}` : k;
    if (v && typeof v === "object" && !Array.isArray(v)) flatParams(v, path, out);
    else out.set(path, JSON.stringify(v, (_, x) => shortestF32(x)));
  }
  return out;
}

// The change from a to b, signed, and whether it is better, worse or
// neither (no change, or a figure without a direction).
function change(a, b, better, digits, unit) {
  const d = b - a;
  const sign = d > 0 ? "+" : d < 0 ? "−" : "±";
  const verdict = d === 0 ? "same" : (d > 0) === (better === "up") ? "better" : "worse";
  return { text: `${sign}${Math.abs(d).toFixed(digits)}${unit}`, verdict, value: d };
}

async function comparePage(signal, a, b) {
  const [bakeA, bakeB] = await Promise.all([json(`/v1/bakes/${a}`), json(`/v1/bakes/${b}`)]);
  const reportOf = (bake) => (bake.report ? json(`/v1/bakes/${bake.id}/report`) : Promise.resolve(null));
  const [reportA, reportB] = await Promise.all([reportOf(bakeA), reportOf(bakeB)]);
  if (signal.aborted) return;
  const head = (...cells) => h("thead", {}, h("tr", {}, ...cells.map((t, i) => h("th", { class: i ? "num" : null }, t))));
  const label = (bake) => h("a", { href: `#/bakes/${bake.id}` }, `#${bake.id}`);

  // What each was baked from.
  const same = (x, y) => (x === y ? "same" : "differs");
  const inputs = h("table", { id: "compare-inputs" },
    h("thead", {}, h("tr", {}, h("th", {}, ""), h("th", {}, label(bakeA)), h("th", {}, label(bakeB)))),
    h("tbody", {},
      h("tr", { "data-input": "character", "data-same": same(bakeA.character, bakeB.character) },
        h("td", {}, "Character"), h("td", {}, characterLabel(bakeA.character)), h("td", {}, characterLabel(bakeB.character))),
      h("tr", { "data-input": "clips", "data-same": same(bakeA.clips.join(), bakeB.clips.join()) },
        h("td", {}, "Clips"), ...[bakeA, bakeB].map((x) => h("td", { class: "mono" }, x.clips.map(short).join(", ") || "in the character file"))),
      h("tr", { "data-input": "method", "data-same": same(bakeA.method, bakeB.method) },
        h("td", {}, "Method"), h("td", {}, bakeA.method), h("td", {}, bakeB.method)),
      h("tr", { "data-input": "state" }, h("td", {}, "State"), h("td", {}, badge(bakeA.state)), h("td", {}, badge(bakeB.state))),
      h("tr", { "data-input": "finished" }, h("td", {}, "Finished"),
        ...[bakeA, bakeB].map((x) => h("td", {}, when(x.finished_at) || "—")))));

  // The parameters that differ; the others folded away.
  const pa = flatParams(bakeA.params);
  const pb = flatParams(bakeB.params);
  const keys = [...new Set([...pa.keys(), ...pb.keys()])].sort();
  const differ = keys.filter((k) => pa.get(k) !== pb.get(k));
  const alike = keys.filter((k) => pa.get(k) === pb.get(k));
  const paramRow = (k) => h("tr", { "data-param": k }, h("td", { class: "mono" }, k),
    h("td", { class: "mono" }, pa.get(k) ?? "—"), h("td", { class: "mono" }, pb.get(k) ?? "—"));
  const params = h("section", { id: "compare-params" },
    h("h2", {}, "Parameters"),
    differ.length
      ? h("table", { id: "params-differ" }, head("Parameter", `#${a}`, `#${b}`), h("tbody", {}, differ.map(paramRow)))
      : h("p", { class: "muted" }, "The same parameters."),
    alike.length ? h("details", {}, h("summary", {}, `${alike.length} parameters the same`),
      h("table", {}, h("tbody", {}, alike.map(paramRow)))) : null);

  // The headline figures side by side, with the change from the first.
  const fa = headline(reportA);
  const fb = new Map(headline(reportB).map((f) => [f.label, f]));
  let quality;
  if (!reportA || !reportB) {
    const missing = [bakeA, bakeB].filter((x) => !x.report).map((x) => `#${x.id} (${x.state})`);
    quality = h("p", { class: "muted", id: "no-quality" }, `No quality to compare: ${missing.join(" and ")} has no report yet.`);
  } else {
    const shared = fa.filter((f) => fb.has(f.label));
    quality = shared.length ? h("table", { id: "compare-quality" },
      head("Figure", `#${a}`, `#${b}`, `Change (#${b} − #${a})`),
      h("tbody", {}, shared.map((f) => {
        const g = fb.get(f.label);
        const c = change(f.value, g.value, f.better, f.digits, f.unit);
        return h("tr", { "data-figure": f.label, "data-change": c.value, "data-verdict": c.verdict },
          h("td", {}, f.label),
          h("td", { class: "num" }, `${f.value.toFixed(f.digits)}${f.unit}`),
          h("td", { class: "num" }, `${g.value.toFixed(g.digits)}${g.unit}`),
          h("td", { class: `num ${c.verdict}` }, c.verdict === "same" ? "same" : `${c.text} (${c.verdict})`));
      })))
      : h("p", { class: "muted", id: "no-quality" }, "The two reports share no figure (different methods).");
  }
  // Each bake's character and method, once where both share it.
  const what = (bake) => [characterLabel(bake.character), " ", h("span", { class: "muted" }, bake.method)];
  const title = bakeA.character === bakeB.character && bakeA.method === bakeB.method
    ? ["Bake ", label(bakeA), " against ", label(bakeB), " ", ...what(bakeB)]
    : ["Bake ", label(bakeA), " ", ...what(bakeA), " against ", label(bakeB), " ", ...what(bakeB)];
  show(h("h1", {}, ...title),
  inputs, params, h("h2", {}, "Quality"), quality);
}

// ---------- routing ----------

async function route() {
  if (/^#token=/.test(location.hash)) return start(); // signing in with another token
  if (page) page.abort();
  page = new AbortController();
  const signal = page.signal;
  // The last page's stream ended with it: until this page opens one (or
  // never, as the versions and compare pages), the server is "online".
  const live = document.getElementById("live");
  if (live.classList.contains("on")) {
    live.classList.remove("on");
    live.textContent = "online";
  }
  const path = location.hash.replace(/^#/, "") || "/";
  const parts = path.split("/").filter(Boolean);
  for (const a of document.querySelectorAll("[data-nav]")) {
    a.classList.toggle("active", a.dataset.nav === (parts[0] || "bakes"));
  }
  try {
    if (parts[0] === "bakes" && parts[1] && !/^[1-9][0-9]*$/.test(parts[1])) {
      show(h("h1", {}, "No such bake"), h("p", {}, `“${parts[1]}” is not a bake number: `,
        h("a", { href: "#/" }, "the bakes"), "."));
    } else if (parts[0] === "bakes" && parts[1]) await bakePage(signal, Number(parts[1]));
    else if (parts[0] === "workers") await workersPage(signal);
    else if (parts[0] === "versions") await versionsPage(signal, parts[1], parts[2]);
    else if (parts[0] === "compare" && /^[1-9][0-9]*$/.test(parts[1]) && /^[1-9][0-9]*$/.test(parts[2])) {
      await comparePage(signal, Number(parts[1]), Number(parts[2]));
    }
    else await bakesPage(signal);
  } catch (e) {
    if (!signal.aborted && !(e instanceof ApiError && e.status === 401)) show(failure(e));
  }
}

// `#token=T` or `#token=T&next=/bakes/7`: T is any token the server
// accepts, percent-encoded where it must be; next is the page to open.
function signInFragment(hash) {
  if (!hash.startsWith("#token=")) return null;
  const out = { token: null, next: "/" };
  for (const part of hash.slice(1).split("&")) {
    const at = part.indexOf("=");
    if (at < 0) continue;
    const key = part.slice(0, at);
    let value = part.slice(at + 1);
    try { value = decodeURIComponent(value); } catch { /* keep it as written */ }
    if (key === "token") out.token = value;
    else if (key === "next" && value.startsWith("/")) out.next = value;
  }
  return out.token ? out : null;
}

async function start() {
  const fragment = signInFragment(location.hash);
  if (fragment) {
    token = fragment.token;
    localStorage.setItem(TOKEN_KEY, token);
    history.replaceState(null, "", `${location.pathname}#${fragment.next}`);
  } else if (location.hash.startsWith("#token=")) {
    // A link without a token: the bakes, not the link again.
    history.replaceState(null, "", `${location.pathname}#/`);
  }
  me = null;
  if (!token) return signIn();
  try {
    me = await json("/v1/whoami");
  } catch (e) {
    if (!(e instanceof ApiError && e.status === 401)) show(failure(e));
    return;
  }
  fill(document.getElementById("who"), `${me.name} (${me.scopes.join(", ")}) `,
    h("a", { href: "#/", onclick: (ev) => { ev.preventDefault(); signOut(); } }, "sign out"));
  route();
}

// Every address change routes, signed in or not: a `#token=` link pasted
// into the sign-in page signs in with it.
window.onhashchange = () => {
  if (/^#token=/.test(location.hash)) start();
  else if (token && me) route();
};
start();
