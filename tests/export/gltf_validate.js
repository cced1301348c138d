// Runs the Khronos glTF Validator (npm package gltf-validator) on each .gltf file named on
// the command line and prints one JSON object: file name -> the report's "issues" part.
// Called by tests/export/validators.py; NODE_PATH points at the installed package.
const fs = require("fs");
const validator = require("gltf-validator");

(async () => {
  const out = {};
  for (const file of process.argv.slice(2)) {
    const bytes = new Uint8Array(fs.readFileSync(file));
    const report = await validator.validateBytes(bytes, { uri: file, format: "gltf", maxIssues: 100 });
    out[file] = report.issues;
  }
  process.stdout.write(JSON.stringify(out));
})().catch((err) => {
  process.stderr.write(String(err) + "\n");
  process.exit(1);
});
