// Validate one .glb with the Khronos glTF validator: node tests/gltf_validate.js FILE.glb
// Prints the validator's JSON report; exit 0 when it has no errors, 1 when it has, 2 on failure.
// Needs the npm package gltf-validator on the module path (NODE_PATH), see the Makefile.
const fs = require("fs");
const validator = require("gltf-validator");
const data = new Uint8Array(fs.readFileSync(process.argv[2]));
validator.validateBytes(data, { maxIssues: 100, writeTimestamp: false })
  .then((report) => { console.log(JSON.stringify(report, null, 1)); process.exit(report.issues.numErrors ? 1 : 0); })
  .catch((err) => { console.error(String(err)); process.exit(2); });
