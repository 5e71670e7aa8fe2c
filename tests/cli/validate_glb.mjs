// Validates GLB files with the Khronos glTF validator (npm gltf-validator): no error and no
// warning in any (infos, such as "KHR_draco_mesh_compression cannot be validated", are fine).
// With --primitives N, the first file's first mesh must have at least N primitives.
//   node tests/cli/validate_glb.mjs [--primitives N] FILE.glb...
import { readFileSync } from 'node:fs';
import validator from 'gltf-validator';

const args = process.argv.slice(2);
let primitives = 0;
if (args[0] === '--primitives') {
  primitives = Number(args[1]);
  args.splice(0, 2);
}
let failed = 0;
for (const [i, file] of args.entries()) {
  const bytes = new Uint8Array(readFileSync(file));
  const report = await validator.validateBytes(bytes);
  const { numErrors, numWarnings } = report.issues;
  const bad = report.issues.messages.filter((m) => m.severity <= 1);
  let note = '';
  if (i === 0 && primitives > 0) {
    const length = new DataView(bytes.buffer).getUint32(12, true);
    const json = JSON.parse(new TextDecoder().decode(bytes.subarray(20, 20 + length)));
    const n = json.meshes[0].primitives.length;
    note = `, ${n} primitives`;
    if (n < primitives) {
      failed++;
      note += ` (expected at least ${primitives})`;
    }
  }
  console.log(`${file}: ${numErrors} errors, ${numWarnings} warnings${note}`);
  for (const m of bad) console.log(`  ${m.code} at ${m.pointer}: ${m.message}`);
  if (numErrors > 0 || numWarnings > 0) failed++;
}
process.exit(failed ? 1 : 0);
