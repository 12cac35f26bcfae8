// Validates a .glb with the Khronos glTF validator (npm gltf-validator) and prints its report's
// counts as one JSON line: {"errors": N, "warnings": N, "infos": N, "hints": N, "messages": [...]}
// Usage: node validate-gltf.js FILE.glb   (NODE_PATH must reach gltf-validator)
'use strict';
const fs = require('fs');
const validator = require('gltf-validator');
const file = process.argv[2];
const bytes = new Uint8Array(fs.readFileSync(file));
validator
  .validateBytes(bytes, { maxIssues: 100, externalResourceFunction: () => Promise.reject(new Error('no external resources')) })
  .then((report) => {
    const i = report.issues;
    const messages = i.messages.map((m) => `${['error', 'warning', 'info', 'hint'][m.severity]} ${m.code} ${m.pointer || ''}: ${m.message}`);
    console.log(JSON.stringify({ errors: i.numErrors, warnings: i.numWarnings, infos: i.numInfos, hints: i.numHints, messages }));
  })
  .catch((e) => {
    console.error(`validate-gltf: ${file}: ${e}`);
    process.exit(2);
  });
