// Benchmark of the live view (not a test): pvcgeld (sim backend, the paper's
// multi-harmonic reference, 1 kHz telemetry) + `pvcgel serve` + the page in
// headless Debian chromium. Prints the page's drawn frames/s and the CPU of
// chromium (all its processes) + pvcgel serve, with the ratios to the targets
// (>= 30 frames/s; < 25 % of one core together).
//
//   node benchmarks/bench_serve.mjs --pvcgeld build/daemon/pvcgeld --pvcgel build/tools/pvcgel \
//        --source . --out build [--seconds 20] [--page-decimation N] [--web-root DIR]
// (--web-root: measure another version of the page, e.g. a variant being tried.)
// PVCGEL_CHROMIUM_FLAGS adds chromium flags (e.g. to try rendering options).
import * as h from "../tests/tools/serve/harness.mjs";

const a = h.args();
const seconds = Number(a.seconds ?? 20);
if (!h.findChromium() || !h.haveModule("chrome-remote-interface") || !h.pageModulesInstalled(a.source))
  h.skip("needs chromium and the npm modules (run .ci/install-deps)");

/** Frames the display compositor drew per second, from a Chrome trace. */
async function compositorFramesPerSecond(client, seconds) {
  let frames = 0;
  client.Tracing.dataCollected(({ value }) => { for (const e of value) if (e.name === "Display::DrawAndSwap" && e.ph === "X") frames++; });
  const complete = new Promise((resolve) => client.Tracing.tracingComplete(resolve));
  await client.Tracing.start({ traceConfig: { includedCategories: ["viz"] } });
  await h.sleep(seconds * 1000);
  await client.Tracing.end();
  await complete;
  return frames / seconds;
}

const daemon = h.startDaemon(a, h.writeConfig(a.source, "bench", "paper-multi"));
const serve = await h.startServe(a, ["--reliable-telemetry", ...(a["page-decimation"] ? ["--page-decimation", a["page-decimation"]] : []),
  ...(a["web-root"] ? ["--web-root", a["web-root"]] : [])]);
const browser = await h.startBrowser();
try {
  const loaded = browser.client.Page.loadEventFired();
  await browser.client.Page.navigate({ url: `http://127.0.0.1:${serve.port}/` });
  await loaded;
  await h.waitFor("the page to run", async () => (await h.evaluate(browser.client, "window.pvcgelStats?.samples ?? 0")) > 3000, 30000);
  await h.sleep(3000);  // past start-up
  const frames0 = await h.evaluate(browser.client, "pvcgelStats.frames");
  const samples0 = await h.evaluate(browser.client, "pvcgelStats.samples");
  const cpu0 = { serve: h.cpuSecondsOfTree(serve.child.pid), chromium: h.cpuSecondsOfTree(browser.child.pid) };
  const t0 = Date.now();
  await h.sleep(seconds * 1000);
  const wall = (Date.now() - t0) / 1000;
  const fps = ((await h.evaluate(browser.client, "pvcgelStats.frames")) - frames0) / wall;
  const rate = ((await h.evaluate(browser.client, "pvcgelStats.samples")) - samples0) / wall;
  const serveCpu = (100 * (h.cpuSecondsOfTree(serve.child.pid) - cpu0.serve)) / wall;
  const chromiumCpu = (100 * (h.cpuSecondsOfTree(browser.child.pid) - cpu0.chromium)) / wall;
  const total = serveCpu + chromiumCpu;
  console.log(`window ${wall.toFixed(1)} s, telemetry reaching the page ${rate.toFixed(0)} samples/s`);
  console.log(`page frames/s      ${fps.toFixed(1)}   target >= 30   ratio ${(fps / 30).toFixed(2)} (>= 1 meets it)`);
  console.log(`CPU pvcgel serve   ${serveCpu.toFixed(1)} % of one core`);
  console.log(`CPU chromium       ${chromiumCpu.toFixed(1)} % of one core (every chromium process)`);
  console.log(`CPU together       ${total.toFixed(1)} %   target < 25 %   ratio ${(total / 25).toFixed(2)} (< 1 meets it)`);
  // The page's own count, checked against the frames the compositor actually
  // drew (after the CPU window: tracing costs CPU).
  const drawn = await compositorFramesPerSecond(browser.client, 3);
  console.log(`compositor frames/s ${drawn.toFixed(1)} (Display::DrawAndSwap in a 3 s trace; the page counted ${fps.toFixed(1)})`);
} finally {
  await browser.client.close().catch(() => {});
  await h.stop(browser.child);
  await h.stop(serve.child);
  await h.stop(daemon);
  process.exit(0);
}
