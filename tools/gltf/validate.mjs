// The Khronos glTF-Validator on files given as arguments: one JSON line per file with the
// counts of errors, warnings, infos and hints and the messages of the first two kinds.
import { readFile } from "node:fs/promises";
import { validateBytes } from "gltf-validator";

for (const path of process.argv.slice(2)) {
  const data = new Uint8Array(await readFile(path));
  const report = await validateBytes(data, {
    uri: path,
    maxIssues: 200,
    externalResourceFunction: () => Promise.reject(new Error("external resources are not used")),
  });
  const issues = report.issues;
  const bad = issues.messages.filter((m) => m.severity <= 1)
    .map((m) => ({ code: m.code, severity: m.severity, message: m.message, pointer: m.pointer }));
  console.log(JSON.stringify({
    path, errors: issues.numErrors, warnings: issues.numWarnings, infos: issues.numInfos,
    hints: issues.numHints, messages: bad, info: report.info,
  }));
}
