// Writes skinning reference positions computed by three.js, an
// implementation independent of aobake, for aobake's skinning tests.
//
//   npm ci && node generate.mjs [FILE.glb|FILE.gltf ...]
//
// Default input: every character in ../../../shared/data. Output: one JSON
// file per input in ../../tests/data/threejs/. For each clip, at three
// times (13 %, 50 % and 87 % of its duration, between keys on purpose), the
// world-space positions of a spread of vertices of every mesh, computed as
// three.js renders them: AnimationMixer.setTime, updateMatrixWorld, then
// Mesh.getVertexPosition (morph targets, then SkinnedMesh.applyBoneTransform)
// and the mesh's matrixWorld.
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';

const here = path.dirname(fileURLToPath(import.meta.url));
const outDir = path.resolve(here, '../../tests/data/threejs');
const FRACTIONS = [0.13, 0.5, 0.87];
// About this many vertex positions per file in all, to keep the repository
// small: fewer per sample for files with many clips.
const POSITIONS_PER_FILE = 6000;

// FileLoader reports progress with ProgressEvent, which Node lacks.
globalThis.ProgressEvent ??= class ProgressEvent extends Event {
  constructor(type, init = {}) { super(type); Object.assign(this, init); }
};

// Images are irrelevant to skinning and cannot load in Node without a DOM:
// drop them, and every texture reference, from the JSON.
function stripTextures(json) {
  delete json.images;
  delete json.textures;
  delete json.samplers;
  for (const m of json.materials ?? []) {
    delete m.normalTexture; delete m.occlusionTexture; delete m.emissiveTexture;
    if (m.pbrMetallicRoughness) {
      delete m.pbrMetallicRoughness.baseColorTexture;
      delete m.pbrMetallicRoughness.metallicRoughnessTexture;
    }
    delete m.extensions;
  }
  return json;
}

function loadInput(file) {
  const bytes = fs.readFileSync(file);
  if (bytes.subarray(0, 4).toString('latin1') !== 'glTF') {
    return { json: stripTextures(JSON.parse(bytes.toString('utf8'))), bin: null };
  }
  const jsonLength = bytes.readUInt32LE(12);
  const json = JSON.parse(bytes.subarray(20, 20 + jsonLength).toString('utf8'));
  let bin = null;
  const binAt = 20 + jsonLength;
  if (binAt + 8 <= bytes.length) {
    const binLength = bytes.readUInt32LE(binAt);
    bin = bytes.subarray(binAt + 8, binAt + 8 + binLength);
  }
  return { json: stripTextures(json), bin };
}

function toGlb(json, bin) {
  const pad = (buf, byte) => Buffer.concat([buf, Buffer.alloc((4 - (buf.length % 4)) % 4, byte)]);
  const jsonChunk = pad(Buffer.from(JSON.stringify(json), 'utf8'), 0x20);
  const chunks = [jsonChunk, bin ? pad(Buffer.from(bin), 0) : null];
  const header = (len, type) => { const h = Buffer.alloc(8); h.writeUInt32LE(len, 0); h.writeUInt32LE(type, 4); return h; };
  const parts = [header(jsonChunk.length, 0x4e4f534a), jsonChunk];
  if (chunks[1]) parts.push(header(chunks[1].length, 0x004e4942), chunks[1]);
  const body = Buffer.concat(parts);
  const head = Buffer.alloc(12);
  head.write('glTF', 0, 'latin1'); head.writeUInt32LE(2, 4); head.writeUInt32LE(12 + body.length, 8);
  const out = Buffer.concat([head, body]);
  return out.buffer.slice(out.byteOffset, out.byteOffset + out.length);
}

async function parse(file) {
  const { json, bin } = loadInput(file);
  const loader = new GLTFLoader();
  const data = bin ? toGlb(json, bin) : JSON.stringify(json);
  return new Promise((resolve, reject) => loader.parse(data, path.dirname(file) + '/', resolve, reject));
}

function round(x) { return Number(x.toPrecision(8)); }

async function generate(file) {
  const gltf = await parse(file);
  const parser = gltf.parser;
  const meshes = [];
  gltf.scene.traverse((o) => { if (o.isMesh) meshes.push(o); });
  const sampleCount = Math.max(1, gltf.animations.length * FRACTIONS.length);
  const perSample = Math.min(128, Math.max(32, Math.floor(POSITIONS_PER_FILE / sampleCount)));
  const perMesh = Math.max(8, Math.ceil(perSample / meshes.length));
  const targets = meshes.map((mesh) => {
    const own = parser.associations.get(mesh) ?? {};
    const node = own.nodes ?? parser.associations.get(mesh.parent)?.nodes;
    const count = mesh.geometry.attributes.position.count;
    const stride = Math.max(1, Math.ceil(count / perMesh));
    const indices = [];
    for (let i = 0; i < count; i += stride) indices.push(i);
    if (indices[indices.length - 1] !== count - 1) indices.push(count - 1);
    return { mesh, node, meshIndex: own.meshes, primitive: own.primitives, indices };
  });
  const mixer = new THREE.AnimationMixer(gltf.scene);
  const samples = [];
  const v = new THREE.Vector3();
  gltf.animations.forEach((clip, clipIndex) => {
    mixer.stopAllAction();
    const action = mixer.clipAction(clip);
    action.reset().play();
    for (const f of FRACTIONS) {
      const time = round(f * clip.duration);
      mixer.setTime(time);
      gltf.scene.updateMatrixWorld(true);
      const primitives = targets.map((t) => {
        const positions = [];
        for (const i of t.indices) {
          t.mesh.getVertexPosition(i, v);
          v.applyMatrix4(t.mesh.matrixWorld);
          positions.push(round(v.x), round(v.y), round(v.z));
        }
        return { node: t.node, mesh: t.meshIndex, primitive: t.primitive, indices: t.indices, positions };
      });
      samples.push({ clip: clipIndex, clip_name: clip.name, time, primitives });
    }
    action.stop();
  });
  return { file: path.basename(file), three: THREE.REVISION, samples };
}

const inputs = process.argv.slice(2);
if (inputs.length === 0) {
  const data = path.resolve(here, '../../../shared/data');
  for (const dir of fs.readdirSync(data).sort()) {
    const full = path.join(data, dir);
    if (!fs.statSync(full).isDirectory()) continue;
    for (const f of fs.readdirSync(full)) if (/\.(glb|gltf)$/.test(f)) inputs.push(path.join(full, f));
  }
}
fs.mkdirSync(outDir, { recursive: true });
for (const file of inputs) {
  const result = await generate(file);
  const out = path.join(outDir, path.basename(file).replace(/\.(glb|gltf)$/, '.json'));
  fs.writeFileSync(out, JSON.stringify(result) + '\n');
  console.log(`${out}: ${result.samples.length} samples`);
}
