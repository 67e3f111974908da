// The bake page's 3D viewer: a bake playing live in WebGL2, written for
// this page (no library). What an engine on WebGL2 does with an asset,
// end to end:
//
// * once per bake, `GET /v1/bakes/{id}/viewer`: the character in its bind
//   pose and its skin, the asset's arrays (the runtime's GPU packing) with
//   the WGSL binding of each, and the program, naga's GLSL ES 3.00 of
//   shaders/wgsl/viewer.wgsl and the family's lookup, with the names naga
//   gave each binding;
// * once per clip, `GET /v1/bakes/{id}/viewer/frames?clip=…`: per frame
//   each joint's world_from_bind matrix and the model's input (a vertex
//   method's weights, which the server's runtime computed from the clip's
//   local joint transforms as an engine's would; the grids' part poses; a
//   cubemap's phase); the previews' camera and looks; the ray-traced truth
//   at the previews' frames;
// * per drawn frame: the palette and the input go into textures (or a
//   uniform), and the vertex shader skins each vertex and looks its AO up
//   with the method's run-time lookup: vertex_ao(v), grid_occlusion at
//   the vertex and on the ground, cubemap_occlusion on the ground.
//
// Both bundles are `AOVW` files: a JSON description, then typed arrays
// the page reads in place.
//
// The canvas element carries `viewer` (show, pixels, state) for tests.

const MODES = [
  ["model", "Model"],
  ["static", "Static average"],
  ["none", "No AO"],
  ["truth", "Ray-traced"],
  ["error", "Error"],
];

// An AOVW bundle: {meta, arrays: {name: typed array}}.
function readBundle(buffer) {
  const view = new DataView(buffer);
  const magic = String.fromCharCode(...new Uint8Array(buffer, 0, 4));
  if (magic !== "AOVW") throw new Error("not a viewer bundle");
  if (view.getUint32(4, true) !== 1) throw new Error(`viewer bundle version ${view.getUint32(4, true)}`);
  const length = view.getUint32(8, true);
  const meta = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 12, length)));
  const base = 12 + length; // where the arrays start, a multiple of 4
  const arrays = {};
  for (const [name, a] of Object.entries(meta.arrays)) {
    arrays[name] = a.type === "f32"
      ? new Float32Array(buffer, base + a.offset, a.count)
      : new Uint32Array(buffer, base + a.offset, a.count);
  }
  return { meta, arrays };
}

// ---------- matrices (column-major, as WebGL reads them) ----------

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const normalize = (a) => { const l = Math.hypot(...a); return a.map((x) => x / l); };

// The view (right-handed, y up) and OpenGL projection (depth -1..1): the
// previews' camera with GL's depth range, so x and y land on the same
// pixels.
function clipFromWorld(eye, target, fovY, aspect, near, far) {
  const f = normalize(sub(target, eye));
  const s = normalize(cross(f, [0, 1, 0]));
  const u = cross(s, f);
  const view = [s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0,
    -dot(s, eye), -dot(u, eye), dot(f, eye), 1];
  const t = 1 / Math.tan(fovY / 2);
  const proj = [t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), -1,
    0, 0, (2 * far * near) / (near - far), 0];
  const out = new Array(16).fill(0);
  for (let c = 0; c < 4; c++) {
    for (let r = 0; r < 4; r++) {
      for (let k = 0; k < 4; k++) out[4 * c + r] += proj[4 * k + r] * view[4 * c + k];
    }
  }
  return out;
}

const srgb = (c) => (c <= 0.0031308 ? 12.92 * c : 1.055 * c ** (1 / 2.4) - 0.055);

// ---------- WebGL ----------

function compile(gl, program) {
  const shader = (type, text) => {
    const s = gl.createShader(type);
    gl.shaderSource(s, text);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  };
  const p = gl.createProgram();
  gl.attachShader(p, shader(gl.VERTEX_SHADER, program.vertex));
  gl.attachShader(p, shader(gl.FRAGMENT_SHADER, program.fragment));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
  gl.useProgram(p);
  // GLSL ES 3.00 has no layout(binding): bind by the names naga gave each
  // WGSL binding. Uniform block b uses binding point b, sampler b unit b.
  for (const r of program.resources) {
    if (r.kind === "block") {
      const index = gl.getUniformBlockIndex(p, r.name);
      if (index !== gl.INVALID_INDEX) gl.uniformBlockBinding(p, index, r.binding);
    } else {
      gl.uniform1i(gl.getUniformLocation(p, r.name), r.binding);
    }
  }
  return p;
}

// An R32UI data texture, `width` texels wide (element i at (i % width,
// i / width)), bound to texture unit `unit`.
function dataTexture(gl, unit, words, width) {
  const t = gl.createTexture();
  gl.activeTexture(gl.TEXTURE0 + unit);
  gl.bindTexture(gl.TEXTURE_2D, t);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
  const texture = { t, unit, width, height: 0 };
  setWords(gl, texture, words);
  return texture;
}

function setWords(gl, texture, words) {
  const height = Math.max(1, Math.ceil(words.length / texture.width));
  const padded = new Uint32Array(texture.width * height);
  padded.set(words);
  gl.activeTexture(gl.TEXTURE0 + texture.unit);
  gl.bindTexture(gl.TEXTURE_2D, texture.t);
  if (height !== texture.height) {
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.R32UI, texture.width, height, 0, gl.RED_INTEGER, gl.UNSIGNED_INT, padded);
    texture.height = height;
  } else {
    gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, texture.width, height, gl.RED_INTEGER, gl.UNSIGNED_INT, padded);
  }
}

function buffer(gl, target, data, usage = gl.STATIC_DRAW) {
  const b = gl.createBuffer();
  gl.bindBuffer(target, b);
  gl.bufferData(target, data, usage);
  return b;
}

// A surface: its vertex array (position, normal, truth, ao at locations
// 0 to 3) and index count.
function surface(gl, positions, normals, indices, vertices) {
  const vao = gl.createVertexArray();
  gl.bindVertexArray(vao);
  const attribute = (location, data, size) => {
    const b = buffer(gl, gl.ARRAY_BUFFER, data, gl.DYNAMIC_DRAW);
    gl.enableVertexAttribArray(location);
    gl.vertexAttribPointer(location, size, gl.FLOAT, false, 0, 0);
    return b;
  };
  const s = {
    vao,
    count: indices.length,
    position: attribute(0, positions, 3),
    normal: normals ? attribute(1, normals, 3) : null,
    truth: attribute(2, new Float32Array(vertices), 1),
    ao: attribute(3, new Float32Array(vertices), 1),
    vertices,
  };
  if (!normals) {
    gl.disableVertexAttribArray(1);
    gl.vertexAttrib3f(1, 0, 1, 0);
  }
  buffer(gl, gl.ELEMENT_ARRAY_BUFFER, indices);
  gl.bindVertexArray(null);
  return s;
}

function setAttribute(gl, b, values) {
  gl.bindBuffer(gl.ARRAY_BUFFER, b);
  gl.bufferSubData(gl.ARRAY_BUFFER, 0, values);
}

// ---------- the viewer ----------

// The viewer of bake `id`: a section that loads itself. `api(path)`
// fetches with the page's token; `h` makes elements.
export function viewerSection(id, { api, h }) {
  const canvas = h("canvas", {
    width: 480, height: 480, class: "viewer-canvas", tabindex: 0,
    "aria-label": "The character in 3D: drag or use the arrow keys to turn it, the wheel or + and − to zoom, Home for the previews' camera",
  });
  const status = h("p", { class: "muted", id: "viewer-status" }, "Loading the viewer…");
  const clipSelect = h("select", { id: "viewer-clip", "aria-label": "clip" });
  const play = h("button", { id: "viewer-play" }, "Pause");
  const slider = h("input", { type: "range", id: "viewer-time", min: 0, max: 0, step: 1, value: 0, "aria-label": "frame" });
  const timeLabel = h("span", { class: "mono", id: "viewer-clock" });
  const modeButtons = MODES.map(([mode, label]) =>
    h("label", {}, h("input", { type: "radio", name: "viewer-mode", value: mode, checked: mode === "model" }), ` ${label}`));
  const reset = h("button", { id: "viewer-reset" }, "Reset camera");
  const errorLine = h("p", { class: "muted", id: "viewer-error" });
  const section = h("section", { id: "viewer", "data-bake": id },
    h("h2", {}, "Viewer"),
    h("div", { class: "viewer" }, canvas,
      h("div", { class: "viewer-controls" },
        h("div", {}, "Clip ", clipSelect, " ", play),
        h("div", {}, slider, " ", timeLabel),
        h("div", { class: "viewer-modes" }, modeButtons),
        h("div", {}, reset),
        errorLine,
        status)));

  const gl = canvas.getContext("webgl2", { antialias: true, preserveDrawingBuffer: true });
  if (!gl) {
    status.textContent = "This browser has no WebGL2: the viewer cannot run here.";
    return section;
  }
  let scene = null; // {meta, arrays, program, textures, character}
  let clip = null; // the frames bundle of the clip shown, and its GL state
  let frame = 0;
  let mode = "model";
  let playing = true;
  let clock = 0; // seconds into the clip
  let orbit = null; // {azimuth, elevation, distance}
  let last = null;
  const ubo = { shading: null, viewer: null };

  const fail = (e) => { status.textContent = `The viewer failed: ${e.message}`; status.classList.add("error"); };

  async function loadScene() {
    const res = await api(`/v1/bakes/${id}/viewer`);
    const { meta, arrays } = readBundle(await res.arrayBuffer());
    const program = compile(gl, meta.program);
    const width = meta.texture_width;
    const m = meta.model;
    // The family's arrays at their WGSL bindings (uniform blocks at binding
    // points, textures at units of the same number).
    for (const u of m.uniforms) gl.bindBufferBase(gl.UNIFORM_BUFFER, u.binding, buffer(gl, gl.UNIFORM_BUFFER, arrays[u.array]));
    for (const t of m.textures) dataTexture(gl, t.binding, arrays[t.array], width);
    const textures = {
      input: m.frame.kind === "texture" ? dataTexture(gl, m.frame.binding, new Uint32Array(Math.max(1, m.frame.floats)), width) : null,
      skin: dataTexture(gl, 8, arrays.skin, width),
      palette: dataTexture(gl, 9, new Uint32Array(16 * Math.max(1, meta.joints)), width),
    };
    ubo.shading = buffer(gl, gl.UNIFORM_BUFFER, new Uint32Array(56), gl.DYNAMIC_DRAW);
    ubo.viewer = buffer(gl, gl.UNIFORM_BUFFER, new Uint32Array(4), gl.DYNAMIC_DRAW);
    gl.bindBufferBase(gl.UNIFORM_BUFFER, 6, ubo.shading);
    gl.bindBufferBase(gl.UNIFORM_BUFFER, 7, ubo.viewer);
    const character = surface(gl, arrays.positions, arrays.normals, arrays.indices, meta.vertices);
    scene = { meta, arrays, program, textures, character, zeros: new Float32Array(meta.vertices) };
    for (const c of meta.clips) clipSelect.append(h("option", { value: c.name }, c.name));
    const staticInput = section.querySelector("input[name=viewer-mode][value=static]");
    if (!arrays.static_ao) {
      staticInput.disabled = true;
      staticInput.parentElement.title = "the vertex methods bake a static average; this method's is in its report";
    }
    const notes = [];
    if (meta.morphs) notes.push("Unlike the previews, the viewer does not apply morph targets.");
    if (meta.computed_normals) {
      notes.push("Where the file has no normals, the viewer skins the bind pose's (the previews recompute them every frame).");
    }
    const shades = [m.model_on.character ? "the character" : null, m.model_on.ground ? "the ground" : null]
      .filter(Boolean).join(" and ");
    status.textContent = `${meta.method}: ${meta.vertices} vertices; the model shades ${shades}, looked up per vertex in the vertex shader.`
      + (notes.length ? ` ${notes.join(" ")}` : "");
  }

  async function loadClip(name) {
    const res = await api(`/v1/bakes/${id}/viewer/frames?clip=${encodeURIComponent(name)}`);
    const { meta, arrays } = readBundle(await res.arrayBuffer());
    if (clip) gl.deleteVertexArray(clip.ground.vao);
    const g = meta.ground_vertices;
    clip = {
      meta,
      arrays,
      ground: surface(gl, arrays.ground_positions, null, arrays.ground_indices, g),
      groundZeros: new Float32Array(g),
    };
    clipSelect.value = name;
    slider.max = meta.times.length - 1;
    orbit = homeOrbit(meta.camera);
    const traced = meta.errors.length > 0;
    for (const input of section.querySelectorAll("input[name=viewer-mode]")) {
      if (input.value === "truth" || input.value === "error") {
        input.disabled = !traced;
        input.parentElement.title = traced ? "" : "the previews traced another clip";
        if (!traced && input.checked) setMode("model");
      }
    }
    setFrame(meta.start || 0);
  }

  // The orbit at the previews' camera.
  function homeOrbit(c) {
    const offset = sub(c.eye, c.target);
    const distance = Math.hypot(...offset);
    return { azimuth: Math.atan2(offset[0], offset[2]), elevation: Math.asin(offset[1] / distance), distance, home: true };
  }

  // The orbit's elevation kept between straight down and the lowest
  // that leaves the eye above the ground (a drag or a zoom never puts the
  // camera under it).
  function elevationIn(elevation, distance) {
    const c = clip.meta.camera;
    const above = (c.ground_y + 0.02 * distance - c.target[1]) / distance;
    const lowest = Math.max(-1.5, Math.asin(Math.max(-1, Math.min(1, above))));
    return Math.max(lowest, Math.min(1.5, elevation));
  }

  function cameraEye() {
    const c = clip.meta.camera;
    // The previews' eye exactly while the camera has not been moved.
    if (orbit.home) return c.eye;
    const { azimuth, distance } = orbit;
    const elevation = elevationIn(orbit.elevation, distance);
    return [c.target[0] + distance * Math.sin(azimuth) * Math.cos(elevation),
      c.target[1] + distance * Math.sin(elevation),
      c.target[2] + distance * Math.cos(azimuth) * Math.cos(elevation)];
  }

  function setFrame(i) {
    frame = Math.max(0, Math.min(i, clip.meta.times.length - 1));
    slider.value = frame;
    const t = clip.meta.times[frame];
    clock = t;
    const truth = clip.meta.truth[frame];
    timeLabel.textContent = `${t.toFixed(3)} s / ${clip.meta.duration.toFixed(3)} s`;
    if (truth !== null) {
      const e = clip.meta.errors[truth];
      const part = (what, x) => (x ? `${what} RMSE ${x.rmse.toFixed(4)}, worst ${x.max.toFixed(4)}` : null);
      errorLine.textContent = "Error against ray-traced AO at this frame: "
        + [part("character", e.character), part("ground", e.ground)].filter(Boolean).join("; ") + ".";
    } else {
      errorLine.textContent = "No ray-traced truth for this clip: the previews trace one clip, and only it shows the ground's occlusion, the truth and the error.";
    }
    draw();
  }

  function draw() {
    if (!scene || !clip) return;
    const { meta: cm, arrays: ca } = clip;
    const sm = scene.meta;
    const truthRow = cm.truth[frame];
    const effective = truthRow === null && (mode === "truth" || mode === "error") ? "model" : mode;
    // The frame's palette and model input.
    const j = sm.joints;
    setWords(gl, scene.textures.palette, new Uint32Array(ca.palettes.buffer, ca.palettes.byteOffset + 4 * frame * 16 * j, 16 * j));
    const n = cm.inputs;
    const input = ca.inputs.subarray(frame * n, (frame + 1) * n);
    if (scene.textures.input) {
      setWords(gl, scene.textures.input, new Uint32Array(input.buffer, input.byteOffset, Math.max(1, n)));
    }
    const phase = sm.model.frame.kind === "phase" ? input[0] : 0;
    // Per surface: its truth, and the AO it shows where the model does not
    // shade it (its truth, as in the previews; a vertex method's static
    // average; or none).
    const v = sm.vertices;
    const g = cm.ground_vertices;
    const rows = (all, row, count, zeros) => (row === null ? zeros : all.subarray(row * count, (row + 1) * count));
    const truth = rows(ca.truth, truthRow, v, scene.zeros);
    const groundTruth = rows(ca.ground_truth, truthRow, g, clip.groundZeros);
    const ch = scene.character;
    const shown = [
      [ch, truth, scene.zeros, sm.model.model_on.character, ca.shading_character, 1],
      [clip.ground, groundTruth, clip.groundZeros, sm.model.model_on.ground, ca.shading_ground, 0],
    ];
    const c = cm.camera;
    const eye = cameraEye();
    // Where the eye is, above the ground's height: what a page test reads.
    canvas.dataset.eyeAboveGround = (eye[1] - c.ground_y).toFixed(5);
    const matrix = clipFromWorld(eye, c.target, c.fov_y, canvas.width / canvas.height, c.near, c.far);
    const panel = effective === "truth" ? 0 : effective === "error" ? 2 : 1;
    gl.viewport(0, 0, canvas.width, canvas.height);
    const bg = new Float32Array(ca.shading_character.buffer, ca.shading_character.byteOffset + 4 * 48, 3);
    gl.clearColor(srgb(bg[0]), srgb(bg[1]), srgb(bg[2]), 1);
    gl.enable(gl.DEPTH_TEST);
    gl.depthFunc(gl.LESS);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.useProgram(scene.program);
    for (const [s, surfaceTruth, zeros, modelled, words, skinned] of shown) {
      const useModel = modelled && (effective === "model" || effective === "error");
      let ao = surfaceTruth;
      if (effective === "none") ao = zeros;
      else if (effective === "static") ao = skinned ? scene.arrays.static_ao : surfaceTruth;
      setAttribute(gl, s.truth, surfaceTruth);
      setAttribute(gl, s.ao, ao);
      const u = new Uint32Array(words);
      const f = new Float32Array(u.buffer);
      f.set(matrix, 0);
      f.set([...eye, 1], 16);
      u[52] = panel;
      gl.bindBuffer(gl.UNIFORM_BUFFER, ubo.shading);
      gl.bufferSubData(gl.UNIFORM_BUFFER, 0, u);
      const params = new ArrayBuffer(16);
      new Uint32Array(params).set([skinned, sm.influences, useModel ? 1 : 0]);
      new Float32Array(params)[3] = phase;
      gl.bindBuffer(gl.UNIFORM_BUFFER, ubo.viewer);
      gl.bufferSubData(gl.UNIFORM_BUFFER, 0, params);
      gl.bindVertexArray(s.vao);
      gl.drawElements(gl.TRIANGLES, s.count, gl.UNSIGNED_INT, 0);
    }
    gl.bindVertexArray(null);
  }

  function tick(now) {
    if (!section.isConnected) return; // the page went away
    if (playing && clip && last !== null) {
      const d = clip.meta.duration;
      clock = d > 0 ? (clock + (now - last) / 1000) % d : 0;
      const times = clip.meta.times;
      let i = frame;
      if (times[i] > clock) i = 0;
      while (i + 1 < times.length && times[i + 1] <= clock) i++;
      if (i !== frame) {
        const keep = clock;
        setFrame(i);
        clock = keep;
      }
    }
    last = now;
    requestAnimationFrame(tick);
  }

  // Controls.
  clipSelect.addEventListener("change", () => loadClip(clipSelect.value).catch(fail));
  play.addEventListener("click", () => {
    playing = !playing;
    play.textContent = playing ? "Pause" : "Play";
  });
  slider.addEventListener("input", () => {
    playing = false;
    play.textContent = "Play";
    setFrame(Number(slider.value));
  });
  function setMode(m) {
    mode = m;
    for (const input of section.querySelectorAll("input[name=viewer-mode]")) input.checked = input.value === m;
  }
  for (const input of section.querySelectorAll("input[name=viewer-mode]")) {
    input.addEventListener("change", () => { mode = input.value; draw(); });
  }
  reset.addEventListener("click", () => { if (clip) { loadClip(clip.meta.clip).catch(fail); } });
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY };
    try { canvas.setPointerCapture(e.pointerId); } catch (_) { /* a synthetic pointer */ }
  });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag || !orbit) return;
    orbit.azimuth -= (e.clientX - drag.x) * 0.01;
    orbit.elevation = elevationIn(orbit.elevation + (e.clientY - drag.y) * 0.01, orbit.distance);
    orbit.home = false;
    drag = { x: e.clientX, y: e.clientY };
    draw();
  });
  // The keyboard turns and zooms as the pointer does; Home goes back to
  // the previews' camera.
  canvas.addEventListener("keydown", (e) => {
    if (!orbit || !clip || e.altKey || e.ctrlKey || e.metaKey) return;
    const turn = Math.PI / 12; // 15°
    const elevate = (by) => elevationIn(orbit.elevation + by, orbit.distance);
    switch (e.key) {
      case "ArrowLeft": orbit.azimuth += turn; break;
      case "ArrowRight": orbit.azimuth -= turn; break;
      case "ArrowUp": orbit.elevation = elevate(turn); break;
      case "ArrowDown": orbit.elevation = elevate(-turn); break;
      case "+": case "=": orbit.distance /= 1.1; break;
      case "-": case "_": orbit.distance *= 1.1; break;
      case "Home": orbit = homeOrbit(clip.meta.camera); break;
      default: return;
    }
    if (e.key !== "Home") orbit.home = false;
    e.preventDefault();
    draw();
  });
  canvas.addEventListener("wheel", (e) => {
    if (!orbit) return;
    e.preventDefault();
    orbit.distance *= Math.exp(e.deltaY * 0.001);
    orbit.home = false;
    draw();
  }, { passive: false });

  // For tests and scripts: show a clip time in a mode from the previews'
  // camera at a size, and read the pixels back (RGBA rows, top first,
  // base64).
  canvas.viewer = {
    ready: null,
    async show({ clip: name, time, mode: m = "model", size = null }) {
      await this.ready;
      playing = false;
      play.textContent = "Play";
      if (size) { canvas.width = size; canvas.height = size; }
      if (!clip || clip.meta.clip !== name) await loadClip(name);
      orbit.home = true;
      setMode(m);
      const times = clip.meta.times;
      let best = 0;
      for (let i = 0; i < times.length; i++) if (Math.abs(times[i] - time) < Math.abs(times[best] - time)) best = i;
      setFrame(best);
      return { time: times[best], truth: clip.meta.truth[best] !== null };
    },
    pixels() {
      const { width, height } = canvas;
      const rgba = new Uint8Array(4 * width * height);
      gl.readPixels(0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, rgba);
      const rows = new Uint8Array(rgba.length);
      for (let y = 0; y < height; y++) rows.set(rgba.subarray(4 * (height - 1 - y) * width, 4 * (height - y) * width), 4 * y * width);
      let text = "";
      for (let i = 0; i < rows.length; i += 0x8000) text += String.fromCharCode(...rows.subarray(i, i + 0x8000));
      return { width, height, rgba: btoa(text) };
    },
    state: () => ({ clip: clip?.meta.clip, duration: clip?.meta.duration, frame, time: clip?.meta.times[frame], mode, playing }),
  };
  canvas.viewer.ready = (async () => {
    await loadScene();
    const first = scene.meta.preview_clip || scene.meta.clips[0]?.name;
    if (first === undefined) {
      status.textContent = "The character has no clips to play.";
      return;
    }
    await loadClip(first);
    section.dataset.ready = "yes";
    requestAnimationFrame(tick);
  })().catch((e) => { fail(e); throw e; });
  canvas.viewer.ready.catch(() => {});
  return section;
}
