// Print OUT_DIR/browser-bench.json as a markdown table (run.sh's last step),
// and record run.sh's wall time in it.
//
//   node web/bench/table.mjs OUT_DIR/browser-bench.json [RUN_SH_WALL_SECONDS]

import { readFileSync, writeFileSync } from "node:fs";

const [file, wall] = process.argv.slice(2);
const bench = JSON.parse(readFileSync(file, "utf8"));
if (wall) {
  bench.run_sh_wall_s = Number(wall);
  writeFileSync(file, JSON.stringify(bench, null, 1));
}

const ms = (x) => (x === undefined || x === null ? "" : x >= 100 ? Math.round(x).toLocaleString("en-US") : x.toFixed(1));
const num = (x, digits) => (x === undefined || x === null ? "" : x.toPrecision(digits));
const size = (r) => {
  const f = bench.frames?.find((f) => f.label === r.frame);
  return f ? `${f.width}×${f.height}` : r.frame;
};

const lines = [
  "| method | backend | size | ms per frame (median) | runs | ms, inputs on GPU | relMSE | light |",
  "|---|---|---|---:|---:|---:|---:|---:|",
];
for (const r of bench.results) {
  if (r.method === "reference") continue;
  const backend = r.error
    ? "did not run"
    : r.method === "noisy"
      ? ""
      : r.method === "filterjit"
        ? "WebGPU"
        : r.method === "oidn-native"
          ? r.backend
          : `${r.backend === "webgpu" ? "WebGPU" : r.backend === "webgl" ? "WebGL" : r.backend}${r.tiled ? ", 256² tiles" : ""}${
              r.tried?.length ? ` (fallback: ${r.tried.map((t) => t.backend).join(", ")} failed)` : ""
            }`;
  const runs = r.ms ? `${r.warmup}+${r.ms.length}` : "";
  lines.push(
    `| ${r.name ?? r.method} | ${backend} | ${size(r)} | ${r.error ? "—" : ms(r.median_ms)} | ${runs} | ${ms(r.gpu_resident_median_ms)} | ${r.error ? "—" : num(r.relmse, 3)} | ${r.error ? "—" : num(r.light, 4)} |`,
  );
}
console.log(lines.join("\n"));
const failed = bench.results.filter((r) => r.error);
for (const r of failed) console.log(`\n${r.name ?? r.method} at ${size(r)} did not run: ${r.error}`);
const frames = bench.frames ?? [];
// The render's estimate of its reference's own error sums the channels; here it is per channel, as relMSE above.
const residual = (f) => (f.reference_residual_relmse ? `, its own relMSE ≈ ${(f.reference_residual_relmse / 3).toPrecision(2)}` : "");
console.log(
  `\n${frames
    .map(
      (f) =>
        `${f.width}×${f.height}: ${f.scene}, ${f.spp} spp, reference ${f.reference_spp} spp${residual(f)}` +
        (f.rendered !== `${f.width}x${f.height}` ? ` (${f.rendered} rendered, mirrored to ${f.height} rows; errors on the rendered rows)` : ""),
    )
    .join("; ")}.`,
);
console.log(
  "ms per frame: warm-up + timed runs, Float32Arrays in to a Float32Array out, GPU work awaited. " +
    "relMSE: mean over pixels and RGB of (o − r)² / (r² + 0.01); light: mean luminance over the reference's.",
);
if (wall) console.log(`run.sh wall time: ${Math.round(wall)} s`);
