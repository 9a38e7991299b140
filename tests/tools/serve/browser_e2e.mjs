// The live page in Debian's headless chromium (Chrome DevTools Protocol) against
// the real pvcgeld (sim backend, the paper's multi-harmonic reference) and
// pvcgel serve: state text, a growing sample count, four plots with data (a
// screenshot in the build tree), "no daemon" and recovery after a restart.
import { writeFileSync } from "node:fs";
import path from "node:path";
import * as h from "./harness.mjs";

const a = h.args();
if (!h.findChromium()) h.skip("chromium is not installed (run .ci/install-deps)");
if (!h.haveModule("chrome-remote-interface")) h.skip("npm modules missing in tests/tools/serve (run .ci/install-deps)");
if (!h.pageModulesInstalled(a.source)) h.skip("uPlot missing in tools/serve/web/node_modules (run .ci/install-deps)");
const RIG = "browser";
const config = h.writeConfig(a.source, RIG, "paper-multi");

const text = (client, id) => h.evaluate(client, `document.getElementById(${JSON.stringify(id)})?.textContent ?? ""`);
const samples = async (client) => Number(await text(client, "samples"));

/** Pixels of each plot's series colours, counted on the four uPlot canvases. */
const plotInk = (client) => h.evaluate(client, `(() => {
  const colours = [[[0,102,204]], [[204,51,0]], [[102,153,0]], [[153,51,153]]];  // y, e, u, d_hat (r's black is also the axes' text)
  return [...document.querySelectorAll('#plots canvas.moving')].map((cv, i) => {
    const d = cv.getContext('2d').getImageData(0, 0, cv.width, cv.height).data;
    let n = 0;
    // The canvases are opaque: an antialiased line pixel is the series colour
    // blended over white, a = (255 - pixel) / (255 - colour) the same in every channel.
    const blend = (p, c) => {
      const a = [0, 1, 2].filter((k) => c[k] < 200).map((k) => (255 - d[p + k]) / (255 - c[k]));
      return Math.min(...a) > 0.4 && Math.max(...a) - Math.min(...a) < 0.2 && [0, 1, 2].every((k) => c[k] < 200 || d[p + k] > 200);
    };
    for (let p = 0; p < d.length; p += 4)
      for (const c of colours[i] ?? []) if (blend(p, c)) { n++; break; }
    return n;
  });
})()`);

let daemon = h.startDaemon(a, config);
const second = h.startDaemon(a, h.writeConfig(a.source, "second", null));  // an idle second rig for the picker
const serve = await h.startServe(a, ["--allow-control", "--reliable-telemetry"]);
const browser = await h.startBrowser();
const { client } = browser;
try {
  const loaded = client.Page.loadEventFired();
  await client.Page.navigate({ url: `http://127.0.0.1:${serve.port}/` });
  await loaded;
  await h.waitFor("the state text RUNNING", async () => (await text(client, "state")) === "RUNNING", 20000);
  h.check(true, `state text: ${await text(client, "state")}, mode ${await text(client, "mode")}, high voltage ${await text(client, "hv")}`);
  h.check(/cycles at 1000 Hz/.test(await text(client, "loop")), `loop statistics from Status: ${await text(client, "loop")}`);
  h.check(await h.evaluate(client, `!document.getElementById('controls').hidden`), "control buttons shown (server allows control)");
  const rigs = await h.waitFor("both rigs in the picker", async () => {
    const r = await h.evaluate(client, `[...document.getElementById('rig').options].map((o) => o.value).join(",")`);
    return r.split(",").length === 2 ? r : null;
  }, 10000);
  h.check(rigs === "browser,second", `rig picker lists both rigs (${rigs})`);
  await h.evaluate(client, `(() => { const p = document.getElementById('rig'); p.value = 'second'; p.dispatchEvent(new Event('change')); })()`);
  await h.waitFor("the second rig's state DISABLED", async () => (await text(client, "state")) === "DISABLED", 5000);
  h.check(true, "picking the idle second rig shows its state: DISABLED");
  await h.stop(second, "SIGTERM");
  await h.evaluate(client, `(() => { const p = document.getElementById('rig'); p.value = 'browser'; p.dispatchEvent(new Event('change')); })()`);
  await h.waitFor("RUNNING again on the first rig", async () => (await text(client, "state")) === "RUNNING", 5000);
  const n0 = await samples(client);
  await h.sleep(2000);
  const n1 = await samples(client);
  h.check(n1 - n0 > 1500, `the sample count grows: ${n0} -> ${n1} in 2 s`);
  await h.sleep(5000);  // most of the 10 s window, for the screenshot
  const ink = await plotInk(client);
  h.check(ink.length === 4 && ink.every((n) => n > 200), `four plots with data (series pixels per plot: ${ink.join(", ")})`);
  h.check(/mean \|e\| [0-9.]+ um/.test(await text(client, "tracking")), `tracking statistics: ${await text(client, "tracking")}`);
  const shot = await client.Page.captureScreenshot({ format: "png" });
  const file = path.join(a.out, "serve_page.png");
  writeFileSync(file, Buffer.from(shot.data, "base64"));
  console.log(`screenshot: ${file}`);
  const fps = await h.evaluate(client, `new Promise((r) => { const f0 = pvcgelStats.frames; setTimeout(() => r((pvcgelStats.frames - f0) / 2), 2000); })`);
  console.log(`measured: page draws ${fps.toFixed(1)} frames/s`);
  // The plots scroll between draws: the canvases move, and the right edge stays
  // just behind the newest sample (the page's display lag, 0.25 s).
  const moves = await h.evaluate(client, `new Promise((r) => { const c = document.querySelector('#plots canvas.moving');
    let last = c.style.transform, n = 0;
    const t = setInterval(() => { if (c.style.transform !== last) { n++; last = c.style.transform; } }, 10);
    setTimeout(() => { clearInterval(t); r(n); }, 500); })`);
  h.check(moves >= 5, `the plots scroll between draws: the first canvas moved ${moves} times in 0.5 s`);
  const lags = await h.evaluate(client, `new Promise((r) => { const l = []; const t = setInterval(() => l.push(pvcgelStats.lag_s), 50); setTimeout(() => { clearInterval(t); r(l); }, 1000); })`);
  h.check(lags.every((l) => l >= 0 && l < 0.6), `the right edge is 0-0.6 s behind the newest sample: ${Math.min(...lags).toFixed(3)}-${Math.max(...lags).toFixed(3)} s`);

  // The daemon goes away: "no daemon"; it comes back: the page recovers by itself.
  const gone = await h.stop(daemon, "SIGTERM");
  h.check(gone.code === 0, "pvcgeld stopped");
  await h.waitFor("the state text 'no daemon'", async () => (await text(client, "state")) === "no daemon", 8000);
  h.check(true, "state text: no daemon");
  daemon = h.startDaemon(a, config);
  await h.waitFor("RUNNING again after the restart", async () => (await text(client, "state")) === "RUNNING", 20000);
  const m0 = await samples(client);
  await h.sleep(1500);
  const m1 = await samples(client);
  h.check(m1 - m0 > 1000, `recovered: the sample count grows again (${m0} -> ${m1} in 1.5 s)`);
  console.log("passed");
} catch (e) {
  console.error(e);
  console.error(`--- serve output:\n${serve.child.output}`);
  process.exitCode = 1;
} finally {
  await client.close().catch(() => {});
  await h.stop(browser.child, "SIGTERM");
  await h.stop(serve.child, "SIGTERM");
  await h.stop(daemon, "SIGTERM");
  await h.stop(second, "SIGTERM");
  process.exit(process.exitCode ?? 0);
}
