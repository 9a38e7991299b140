// Shared by the `pvcgel serve` end-to-end tests and benchmarks/bench_serve.mjs:
// the real pvcgeld (sim backend) and pvcgel serve on loopback DDS, headless
// chromium driven over the Chrome DevTools Protocol.
import { spawn, execFileSync } from "node:child_process";
import { existsSync, mkdtempSync, readFileSync, writeFileSync } from "node:fs";
import { createRequire } from "node:module";
import { tmpdir } from "node:os";
import path from "node:path";

export const require = createRequire(import.meta.url);

/** ctest's way to say "skipped" (SKIP_RETURN_CODE 77): never reported as passed. */
export function skip(reason) {
  console.log(`SKIPPED: ${reason}`);
  process.exit(77);
}

export function fail(message) {
  console.error(`FAILED: ${message}`);
  process.exitCode = 1;
  throw new Error(message);
}

export function check(ok, message) {
  if (!ok) fail(message);
  console.log(`ok: ${message}`);
}

/** --pvcgeld PATH --pvcgel PATH --source DIR --out DIR */
export function args() {
  const a = {};
  for (let i = 2; i + 1 < process.argv.length; i += 2) a[process.argv[i].replace(/^--/, "")] = process.argv[i + 1];
  for (const k of ["pvcgeld", "pvcgel", "source", "out"]) if (!a[k]) throw new Error(`missing --${k}`);
  return a;
}

/** Like tests/support/subprocess.hpp's unique_dds_domain: one domain per test process
 *  (PVCGEL_TEST_DDS_DOMAIN chooses it, for a machine shared with other engineers' runs). */
export const domain = process.env.PVCGEL_TEST_DDS_DOMAIN ? Number(process.env.PVCGEL_TEST_DDS_DOMAIN)
  : 30 + ((process.pid * 7) % 190);

export const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

export async function waitFor(what, predicate, timeoutMs, stepMs = 100) {
  const end = Date.now() + timeoutMs;
  for (;;) {
    const v = await predicate();
    if (v) return v;
    if (Date.now() > end) fail(`timed out after ${timeoutMs} ms waiting for ${what}`);
    await sleep(stepMs);
  }
}

/** The shipped sim config on `domain` as `rig`, with `trajectory` (null: idle DISABLED). */
export function writeConfig(source, rig, trajectory) {
  let text = readFileSync(path.join(source, "config/pvcgeld-sim.toml"), "utf8");
  text = text.replace(/\ntrajectory = [^\n]*/, trajectory ? `\ntrajectory = "${trajectory}"` : "\n");
  text = text.replace(/\ndomain = 0/, `\ndomain = ${domain}`);
  text = text.replace(/\nrig_id = "rig1"/, `\nrig_id = "${rig}"`);
  text = text.replace('config = "cyclonedds-loopback.xml"', `config = "${path.join(source, "config/cyclonedds-loopback.xml")}"`);
  const dir = mkdtempSync(path.join(tmpdir(), "pvcgel-serve-"));
  const file = path.join(dir, `${rig}.toml`);
  writeFileSync(file, text);
  return file;
}

const children = new Set();
process.on("exit", () => { for (const c of children) try { c.kill("SIGKILL"); } catch { /* gone */ } });

export function start(program, argv, name) {
  const child = spawn(program, argv, { stdio: ["ignore", "pipe", "pipe"] });
  child.output = "";
  child.stdout.on("data", (d) => { child.output += d; });
  child.stderr.on("data", (d) => { child.output += d; });
  child.exited = new Promise((resolve) => child.on("exit", (code, signal) => { children.delete(child); resolve({ code, signal }); }));
  child.label = name;
  children.add(child);
  return child;
}

export async function stop(child, signal = "SIGTERM") {
  child.kill(signal);
  return child.exited;
}

export function startDaemon(a, config) {
  return start(a.pvcgeld, ["--config", config], "pvcgeld");
}

/** pvcgel serve on a free port; resolves with {child, port} once it listens. */
export async function startServe(a, extra = []) {
  const dds = path.join(a.source, "config/cyclonedds-loopback.xml");
  const child = start(a.pvcgel, ["serve", "--port", "0", "--domain", String(domain), "--dds-config", dds, ...extra], "serve");
  const port = await waitFor("pvcgel serve to listen", () => {
    const m = child.output.match(/page http:\/\/127\.0\.0\.1:(\d+)\//);
    if (child.exitCode !== null) fail(`pvcgel serve exited: ${child.output}`);
    return m ? Number(m[1]) : 0;
  }, 10000, 50);
  return { child, port };
}

export function haveModule(name) {
  try { require.resolve(name); return true; } catch { return false; }
}

export function findChromium() {
  for (const c of ["chromium", "chromium-browser"]) {
    try { return execFileSync("which", [c]).toString().trim(); } catch { /* next */ }
  }
  return null;
}

/** Headless chromium with a DevTools port; resolves with {child, client (CDP), Page, Runtime}. */
export async function startBrowser(width = 1280, height = 1000) {
  const exe = findChromium();
  const profile = mkdtempSync(path.join(tmpdir(), "pvcgel-chromium-"));
  const child = start(exe, ["--headless", "--disable-gpu", "--no-sandbox", "--remote-debugging-port=0",
    "--remote-debugging-address=127.0.0.1", `--user-data-dir=${profile}`, "--no-first-run", "--disable-extensions",
    "--disable-background-networking", "--disable-sync", "--metrics-recording-only", "--mute-audio",
    `--window-size=${width},${height}`, ...(process.env.PVCGEL_CHROMIUM_FLAGS ?? "").split(" ").filter(Boolean), "about:blank"],
    "chromium");
  const port = await waitFor("chromium's DevTools endpoint", () => {
    const m = child.output.match(/DevTools listening on ws:\/\/127\.0\.0\.1:(\d+)\//);
    if (child.exitCode !== null) fail(`chromium exited: ${child.output}`);
    return m ? Number(m[1]) : 0;
  }, 20000, 50);
  const CDP = require("chrome-remote-interface");
  const targets = await CDP.List({ host: "127.0.0.1", port });
  const page = targets.find((t) => t.type === "page");
  const client = await CDP({ host: "127.0.0.1", port, target: page });
  await client.Page.enable();
  await client.Runtime.enable();
  await client.Emulation.setDeviceMetricsOverride({ width, height, deviceScaleFactor: 1, mobile: false });
  return { child, client };
}

/** Evaluates `expression` in the page and returns its value. */
export async function evaluate(client, expression) {
  const r = await client.Runtime.evaluate({ expression, returnByValue: true, awaitPromise: true });
  if (r.exceptionDetails) fail(`page error in ${expression}: ${JSON.stringify(r.exceptionDetails)}`);
  return r.result.value;
}

export function pageModulesInstalled(source) {
  return existsSync(path.join(source, "tools/serve/web/node_modules/uplot/dist/uPlot.esm.js"));
}

/** CPU seconds (user + system) of a process and all its descendants, from /proc. */
export function cpuSecondsOfTree(rootPid) {
  const ticks = Number(execFileSync("getconf", ["CLK_TCK"]).toString());
  const stats = new Map();
  for (const d of execFileSync("ls", ["/proc"]).toString().split("\n")) {
    if (!/^\d+$/.test(d)) continue;
    try {
      const s = readFileSync(`/proc/${d}/stat`, "utf8");
      const f = s.slice(s.lastIndexOf(")") + 2).split(" ");
      stats.set(Number(d), { ppid: Number(f[1]), cpu: (Number(f[11]) + Number(f[12])) / ticks });
    } catch { /* exited */ }
  }
  let total = 0;
  const visit = (pid) => {
    total += stats.get(pid)?.cpu ?? 0;
    for (const [p, s] of stats) if (s.ppid === pid) visit(p);
  };
  visit(rootPid);
  return total;
}
