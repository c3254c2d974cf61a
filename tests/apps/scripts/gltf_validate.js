// Validate a glTF/GLB file with the Khronos glTF validator (npm package gltf-validator):
// node gltf_validate.js FILE  → prints {numErrors, numWarnings, messages} as JSON.
"use strict";
const fs = require("fs");
const path = require("path");
const validator = require("gltf-validator");

const file = process.argv[2];
validator
  .validateBytes(new Uint8Array(fs.readFileSync(file)), {
    uri: path.basename(file),
    maxIssues: 100,
    externalResourceFunction: () => Promise.reject(new Error("no external resources")),
  })
  .then((r) => {
    const messages = r.issues.messages.filter((m) => m.severity <= 1);
    console.log(JSON.stringify({
      numErrors: r.issues.numErrors, numWarnings: r.issues.numWarnings, messages,
    }));
  })
  .catch((e) => { console.error(String(e)); process.exit(1); });
