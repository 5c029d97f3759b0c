// The Khronos glTF Validator on files: `node tests/validate_gltf.js FILE...` prints one JSON object,
// file -> {numErrors, numWarnings, numInfos, messages}. The validator is the npm package installed
// beside the demo page (motiongan_jax/demo/static/package.json).
"use strict";
const fs = require("fs");
const path = require("path");
const validator = require(path.join(__dirname, "..", "motiongan_jax", "demo", "static", "node_modules", "gltf-validator"));

async function main() {
  const out = {};
  for (const file of process.argv.slice(2)) {
    const data = new Uint8Array(fs.readFileSync(file));
    const report = await validator.validateBytes(data, { maxIssues: 50 });
    const { numErrors, numWarnings, numInfos, messages } = report.issues;
    out[file] = { numErrors, numWarnings, numInfos, messages };
  }
  process.stdout.write(JSON.stringify(out) + "\n");
}
main().catch((e) => { console.error(String(e)); process.exit(1); });
