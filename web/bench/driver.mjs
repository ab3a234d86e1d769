// Drives the benchmark page in headless Chromium through the DevTools
// protocol, the way tests/common/browser.rs does for the browser tests:
// WebGPU on SwiftShader, the page served over HTTP on the loopback by
// Python's http.server (a secure context, where navigator.gpu exists).
//
//   node --experimental-websocket web/bench/driver.mjs OUT_DIR CASES.json [META.json]
//
// CASES.json: { runs, warmup, cases: [{ name, method, frame, ... }] } (a case
// may set its own runs and warmup); META.json: what run.sh found out about
// the machine. Each case is its own Runtime.evaluate, so one that throws (a
// backend that cannot run a size) is recorded with its message and the
// others still run. Writes OUT_DIR/browser-bench.json; run.sh prints the
// table from it.
// Node 20's WebSocket is behind --experimental-websocket; with it the driver
// needs no package of its own.

import { spawn, execFileSync } from "node:child_process";
import { mkdtempSync, readFileSync, writeFileSync, existsSync, mkdirSync, rmSync } from "node:fs";
import { tmpdir, loadavg } from "node:os";
import { join, resolve, dirname } from "node:path";
import { fileURLToPath } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const web = resolve(here, "..");
const [outDir, casesFile, metaFile] = process.argv.slice(2);
if (!outDir || !casesFile) {
  console.error("usage: node --experimental-websocket driver.mjs OUT_DIR CASES.json [META.json]");
  process.exit(2);
}
const plan = JSON.parse(readFileSync(casesFile, "utf8"));
// What run.sh recorded of the machine and the packages.
const meta = metaFile ? JSON.parse(readFileSync(metaFile, "utf8")) : {};
// What the frames are (frames.py's index), without the file names.
const frames = JSON.parse(readFileSync(join(here, "data", "frames.json"), "utf8")).frames.map(({ files, ...f }) => f);
// Each case's limit: a denoiser on SwiftShader at 1280x720 takes minutes a frame.
const CASE_TIMEOUT_MS = (plan.case_timeout_s ?? 1800) * 1000;

const chromium = process.env.FILTERJIT_CHROMIUM ?? ["chromium", "chromium-browser", "google-chrome"].find((name) => {
  try {
    execFileSync("which", [name], { stdio: "ignore" });
    return true;
  } catch {
    return false;
  }
});
if (!chromium) {
  console.error("no chromium on PATH (apt-get install chromium), nor FILTERJIT_CHROMIUM");
  process.exit(1);
}

const children = [];
const cleanup = () => {
  for (const child of children) if (child.exitCode === null) child.kill("SIGKILL");
};
process.on("exit", cleanup);
process.on("SIGINT", () => process.exit(130));
process.on("SIGTERM", () => process.exit(143));

/** Serve web/ (so the page imports ../filterjit.js itself, not a copy); resolves to its URL. */
function serve() {
  const server = spawn("python3", ["-u", "-m", "http.server", "0", "--bind", "127.0.0.1", "--directory", web], {
    stdio: ["ignore", "pipe", "ignore"],
  });
  children.push(server);
  return new Promise((done, fail) => {
    let text = "";
    server.stdout.on("data", (chunk) => {
      text += chunk;
      // "Serving HTTP on 127.0.0.1 port 41234 (http://127.0.0.1:41234/) ..."
      const port = /port (\d+)/.exec(text)?.[1];
      if (port) done(`http://127.0.0.1:${port}/`);
    });
    server.on("exit", (code) => fail(new Error(`http.server exited (${code}) before saying its port: ${text}`)));
  });
}

/** Start Chromium and resolve to its browser-level DevTools WebSocket URL. */
async function launch(profile) {
  const flags = [
    "--headless=new",
    "--no-sandbox",
    "--no-first-run",
    "--disable-gpu-sandbox",
    "--enable-unsafe-webgpu",
    "--use-webgpu-adapter=swiftshader",
    "--enable-unsafe-swiftshader",
    "--enable-features=Vulkan",
    "--use-vulkan=swiftshader",
    "--disable-vulkan-surface",
    // A page left alone for minutes (one denoiser frame) must not be throttled.
    "--disable-background-timer-throttling",
    "--disable-renderer-backgrounding",
    "--disable-backgrounding-occluded-windows",
    "--remote-debugging-port=0",
    `--user-data-dir=${profile}`,
    "about:blank",
  ];
  const browser = spawn(chromium, flags, { stdio: "ignore" });
  children.push(browser);
  // Chromium writes the port it chose, and the browser's endpoint, into the profile.
  const file = join(profile, "DevToolsActivePort");
  for (let waited = 0; waited < 60000; waited += 100) {
    if (existsSync(file)) {
      const lines = readFileSync(file, "utf8").split("\n");
      if (lines.length >= 2 && lines[1]) return { flags, url: `ws://127.0.0.1:${lines[0]}${lines[1]}` };
    }
    await new Promise((r) => setTimeout(r, 100));
  }
  throw new Error(`chromium wrote no ${file}`);
}

/** One DevTools connection: calls, and the page's console lines passed to `onConsole`. */
async function connect(url, onConsole) {
  const socket = new WebSocket(url);
  await new Promise((done, fail) => {
    socket.onopen = done;
    socket.onerror = () => fail(new Error(`DevTools socket ${url} did not open`));
  });
  let next = 0;
  const waiting = new Map();
  socket.onmessage = (event) => {
    const message = JSON.parse(event.data);
    if (message.id !== undefined && waiting.has(message.id)) {
      const { done, fail } = waiting.get(message.id);
      waiting.delete(message.id);
      if (message.error) fail(new Error(`${JSON.stringify(message.error)}`));
      else done(message.result);
    } else if (message.method === "Runtime.consoleAPICalled") {
      onConsole(message.params.args.map((a) => a.value ?? a.description ?? "").join(" "));
    }
  };
  socket.onclose = () => {
    for (const { fail } of waiting.values()) fail(new Error("DevTools socket closed (did Chromium crash?)"));
    waiting.clear();
  };
  const call = (method, params = {}, sessionId, timeout = 120000) =>
    new Promise((done, fail) => {
      const id = ++next;
      const timer = setTimeout(() => {
        waiting.delete(id);
        fail(new Error(`${method}: no answer in ${timeout / 1000} s`));
      }, timeout);
      waiting.set(id, {
        done: (r) => (clearTimeout(timer), done(r)),
        fail: (e) => (clearTimeout(timer), fail(e)),
      });
      socket.send(JSON.stringify({ id, method, params, ...(sessionId ? { sessionId } : {}) }));
    });
  return { call, close: () => socket.close() };
}

const root = await serve();
const profile = mkdtempSync(join(tmpdir(), "filterjit-bench-"));
const { flags, url } = await launch(profile);
const log = [];
const devtools = await connect(url, (line) => {
  log.push(line);
  // The page's own progress lines; tfjs and the denoiser log plenty besides (all of it
  // goes to OUT_DIR/console.log, and to the terminal with BENCH_VERBOSE=1).
  if (line.startsWith("[bench]")) console.log(line.slice(8));
  else if (process.env.BENCH_VERBOSE) console.log(`   (page) ${line}`);
});
const { product } = await devtools.call("Browser.getVersion");

/**
 * A new tab on the benchmark page, and `evaluate` in it. Each case gets its
 * own: tfjs keeps its backends, and the package its weights, per page (a
 * WebGL case run after a WebGPU one in the same page never finished), and a
 * case that never returns is dropped with its tab.
 */
async function openPage() {
  const { targetId } = await devtools.call("Target.createTarget", { url: "about:blank" });
  const { sessionId } = await devtools.call("Target.attachToTarget", { targetId, flatten: true });
  const page = (method, params, timeout) => devtools.call(method, params, sessionId, timeout);
  await page("Runtime.enable");
  const url = `${root}bench/index.html`;
  const navigated = await page("Page.navigate", { url });
  if (navigated.errorText) throw new Error(`${url}: ${navigated.errorText}`);
  /** The value of an expression in the page (a promise awaited); an exception becomes an Error with its text. */
  const evaluate = async (expression, timeout = 120000) => {
    const result = await page("Runtime.evaluate", { expression, awaitPromise: true, returnByValue: true }, timeout);
    if (result.exceptionDetails) {
      const e = result.exceptionDetails;
      throw new Error(e.exception?.description ?? e.text ?? JSON.stringify(e));
    }
    return result.result.value;
  };
  await evaluate("new Promise(done => document.readyState === 'complete' ? done(true) : addEventListener('load', () => done(true)))");
  if (!(await evaluate("window.benchReady === true"))) throw new Error(`${url}: bench.mjs did not load (see console.log)`);
  const close = () => devtools.call("Target.closeTarget", { targetId }).catch(() => {});
  return { evaluate, close };
}

const first = await openPage();
const environment = await first.evaluate("describe()");
await first.close();
console.log(`${product}; WebGPU adapter: ${JSON.stringify(environment.adapter)}`);

const results = [];
for (const c of plan.cases) {
  const label = `${c.method} at ${c.frame}`;
  console.log(`-- ${label}`);
  const started = Date.now();
  // SwiftShader runs on the CPU: anything else running skews the times, so each case says how busy the machine was.
  const load = loadavg()[0];
  let result;
  let tab;
  try {
    tab = await openPage();
    result = await tab.evaluate(`runCase(${JSON.stringify({ runs: plan.runs, warmup: plan.warmup, ...c })})`, CASE_TIMEOUT_MS);
  } catch (e) {
    result = { ...c, error: String(e.message ?? e).split("\n").slice(0, 6).join("\n") };
    console.log(`   failed: ${result.error}`);
  }
  await tab?.close();
  result.wall_s = (Date.now() - started) / 1000;
  result.load_average_1min = { before: load, after: loadavg()[0] };
  // Previews come back as PNG data URLs: files beside the JSON, named in it.
  if (typeof result.preview === "string") {
    const what = c.method === "denoiser" ? `${c.name}-${result.backend}` : (c.name ?? c.method);
    const name = `${c.frame}-${what}`.replace(/[^A-Za-z0-9@-]+/g, "_").replace(/_(?=-|$)/g, "") + ".png";
    mkdirSync(join(outDir, "previews"), { recursive: true });
    writeFileSync(join(outDir, "previews", name), Buffer.from(result.preview.split(",")[1], "base64"));
    result.preview = `previews/${name}`;
  }
  results.push(result);
  // Written after every case: a crash later keeps what was measured.
  mkdirSync(outDir, { recursive: true });
  writeFileSync(
    join(outDir, "browser-bench.json"),
    JSON.stringify(
      { chromium: product, chromium_flags: flags.filter((f) => !f.startsWith("--user-data-dir")), ...meta, frames, environment, results },
      null,
      1,
    ),
  );
}
writeFileSync(join(outDir, "console.log"), log.join("\n") + "\n");
devtools.close();
// Chromium still writes into its profile while it exits: remove the profile after it has.
const exited = children.map((child) => new Promise((done) => (child.exitCode !== null ? done() : child.on("exit", done))));
cleanup();
await Promise.all(exited);
rmSync(profile, { recursive: true, force: true });
process.exit(0);
