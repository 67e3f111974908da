// Runs the Khronos glTF validator (npm `gltf-validator`) on files and prints
// one JSON line per file: {"file", "errors", "codes": [error codes]}.
// The tests use it to check that their corpus of broken files is broken in
// the validator's eyes too. Install: npm install --prefix tests/tools gltf-validator
// Exit code: 0 when it ran, 2 when the validator is missing.
import fs from 'node:fs';
import path from 'node:path';
import { createRequire } from 'node:module';

const here = path.dirname(new URL(import.meta.url).pathname);
let validator;
for (const dir of [process.env.GLTF_VALIDATOR_DIR, here].filter(Boolean)) {
  try {
    validator = createRequire(path.join(path.resolve(dir), 'noop.js'))('gltf-validator');
    break;
  } catch { /* try the next */ }
}
if (!validator) {
  console.error('gltf-validator is not installed: npm install --prefix tests/tools gltf-validator');
  process.exit(2);
}
for (const file of process.argv.slice(2)) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 0,
    externalResourceFunction: () => Promise.reject(new Error('no external resources')),
  });
  const codes = [...new Set(report.issues.messages.filter((m) => m.severity === 0).map((m) => m.code))];
  console.log(JSON.stringify({ file, errors: report.issues.numErrors, codes }));
}
