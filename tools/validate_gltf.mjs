// Validates glTF files with the Khronos glTF-Validator and prints a summary per file.
//
// Setup (once, anywhere on NODE_PATH or next to this script):
//   npm install gltf-validator
// Run:
//   node tools/validate_gltf.mjs animations/default.gltf [more.gltf ...]
// (if gltf-validator is installed elsewhere, e.g. in /tmp:
//   NODE_PATH=/tmp/node_modules node tools/validate_gltf.mjs animations/default.gltf)
//
// Exits 1 when any file has errors or warnings. Not used by the Rust tests.

import fs from 'node:fs';
import path from 'node:path';
import { createRequire } from 'node:module';

// createRequire honours NODE_PATH, which plain ESM imports do not.
const require = createRequire(import.meta.url);
const validator = require('gltf-validator');

async function validate(file) {
  const dir = path.dirname(file);
  const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
    uri: path.basename(file),
    maxIssues: 0,
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.join(dir, decodeURIComponent(uri)), (err, data) =>
          err ? reject(err.toString()) : resolve(new Uint8Array(data)));
      }),
  });
  const { issues } = report;
  console.log(
    `${file}: ${issues.numErrors} errors, ${issues.numWarnings} warnings, ` +
      `${issues.numInfos} infos, ${issues.numHints} hints ` +
      `(validator ${report.validatorVersion})`);
  for (const m of issues.messages) {
    console.log(`  [${['error', 'warning', 'info', 'hint'][m.severity]}] ${m.code} ${m.pointer ?? ''}: ${m.message}`);
  }
  return issues.numErrors === 0 && issues.numWarnings === 0;
}

const files = process.argv.slice(2);
if (files.length === 0) {
  console.error('usage: node tools/validate_gltf.mjs FILE.gltf [...]');
  process.exit(2);
}
let ok = true;
for (const file of files) ok = (await validate(file)) && ok;
process.exit(ok ? 0 : 1);
