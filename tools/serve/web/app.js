// The live page: a thin client of pvcgel serve's Foxglove WebSocket protocol
// (foxglove.websocket.v1), the same channels and services Foxglove Studio sees.
import uPlot from "/uplot/uPlot.esm.js";

const WINDOW_S = 10;          // plots and statistics cover the last 10 s of loop time
const NO_DAEMON_AFTER_MS = 2500;  // Status comes at >= 2 Hz
const $ = (id) => document.getElementById(id);

const stats = { frames: 0, samples: 0, batches: 0, gaps: 0 };
window.pvcgelStats = stats;   // read by the tests and the benchmark

let ws = null;
let allowControl = false;
let defaultRig = null;      // pvcgel serve --rig: shown first when present
const channels = new Map();   // channel id -> {rig, topic}
const services = new Map();   // service name -> id
const subscriptions = new Map();  // subscription id -> channel id
let nextSubscription = 1;
let nextCall = 1;
const calls = new Map();      // call id -> label
let rig = null;
let lastStatusMs = 0;
let lastStatus = null;

// Plot data: the window's plotted samples in typed arrays (no per-batch arrays
// to collect); exact |e| sums per batch for the statistics.
const KEYS = ["t", "r", "y", "e", "u", "d"];
const BATCH_KEYS = { t: "t_s", r: "r_um", y: "y_um", e: "e_um", u: "u_V", d: "d_hat" };

/** Columns of samples in a buffer twice the window's size, appended at the end;
 *  when the end is reached the live window moves to the front (one copy per
 *  window), so the plots get contiguous subarray views and nothing is copied per frame. */
class WindowColumns {
  constructor(capacity) {
    this.capacity = capacity;
    this.cols = Object.fromEntries(KEYS.map((k) => [k, new Float64Array(2 * capacity)]));
    this.start = 0;
    this.end = 0;
  }
  get length() { return this.end - this.start; }
  lastT() { return this.length ? this.cols.t[this.end - 1] : null; }
  clear() { this.start = this.end = 0; }
  append(b) {
    const n = b.t_s.length;
    if (this.length + n > this.capacity) this.grow(2 * (this.length + n));
    if (this.end + n > 2 * this.capacity) this.compact();
    for (const k of KEYS) {
      const src = b[BATCH_KEYS[k]], dst = this.cols[k];
      // null (a faulted sensor) -> NaN: the canvas skips non-finite points.
      for (let i = 0; i < n; i++) dst[this.end + i] = src[i] ?? NaN;
    }
    this.end += n;
  }
  dropBefore(t0) {
    const t = this.cols.t;
    while (this.start < this.end && t[this.start] < t0) this.start++;
  }
  compact() {
    for (const k of KEYS) this.cols[k].copyWithin(0, this.start, this.end);
    this.end -= this.start;
    this.start = 0;
  }
  grow(capacity) {
    const old = this.cols, from = this.start, to = this.end;
    this.capacity = capacity;
    this.cols = Object.fromEntries(KEYS.map((k) => [k, new Float64Array(2 * capacity)]));
    for (const k of KEYS) this.cols[k].set(old[k].subarray(from, to));
    this.start = 0;
    this.end = to - from;
  }
  view(k) { return this.cols[k].subarray(this.start, this.end); }
}

const cols = new WindowColumns(2048);   // grows if a smaller --page-decimation needs more
let batches = [];             // {t, n, sumAbs, sumSq, max}
let dirty = false;

function clearData() {
  cols.clear();
  batches = [];
  dirty = true;
}

const xRange = () => {
  const end = cols.lastT() ?? WINDOW_S;
  return [Math.max(0, end - WINDOW_S), Math.max(WINDOW_S, end)];
};

const PLOT_HEIGHT = 150;

function makePlot(title, series, yLabel, legend) {
  const width = Math.max(400, $("plots").clientWidth - 10);
  return new uPlot({
    title, width, height: PLOT_HEIGHT,
    scales: { x: { time: false, range: () => xRange() } },
    // What a browser without a GPU redraws in software 32 times a second, kept
    // lean: tick labels every second and every ~30 px (each is text shaped and
    // rasterised again per frame), lines, grid and ticks 1 px wide (a wider
    // antialiased stroke of ~1000 points costs several times as much).
    axes: [{ label: "loop time (s)", space: 90, size: 30, labelSize: 20, grid: { width: 1 }, ticks: { width: 1 } },
      { label: yLabel, space: 30, grid: { width: 1 }, ticks: { width: 1 } }],
    series: [{ label: "t (s)" }, ...series],
    legend: { show: legend, live: false },
    cursor: { show: false },
  }, [[]], $("plots"));
}

const plots = [
  // r dashed on top of y: both show where they coincide.
  { plot: makePlot("displacement y (blue) and reference r (black), um", [{ label: "y (um)", stroke: "#06c" }, { label: "r (um)", stroke: "#222", dash: [6, 6] }], "um", true), keys: ["y", "r"] },
  { plot: makePlot("tracking error e = r - y, um", [{ label: "e (um)", stroke: "#c30" }], "um", false), keys: ["e"] },
  { plot: makePlot("amplifier voltage u, V", [{ label: "u (V)", stroke: "#690" }], "V", false), keys: ["u"] },
  { plot: makePlot("disturbance estimate d_hat (linear-block input units)", [{ label: "d_hat", stroke: "#939" }], "d_hat", false), keys: ["d"] },
];

// Everything the page changes is changed in one animation frame per batch
// (pvcgel serve sends 32 a second: >= 30 frames/s, and not more, since in a
// browser without a GPU every frame, even one that changes nothing, costs
// about a millisecond of CPU); text only every 250 ms.
let frameRequested = false;
function requestFrame() {
  if (frameRequested) return;
  frameRequested = true;
  requestAnimationFrame(render);
}

/** Sets text only when it changed (an unchanged assignment still relayouts). */
function setText(id, text, className) {
  const el = $(id);
  if (el.textContent !== text) el.textContent = text;
  if (className !== undefined && el.className !== className) el.className = className;
}

const TEXT_EVERY_MS = 250;   // text changes force a relayout: 4 per second are plenty to read
let lastTextMs = 0;

function render(now) {
  frameRequested = false;
  if (dirty) {
    dirty = false;
    for (const p of plots) p.plot.setData([cols.view("t"), ...p.keys.map((k) => cols.view(k))]);
    stats.frames++;
  }
  if (now - lastTextMs < TEXT_EVERY_MS) return;
  lastTextMs = now;
  showTracking();
  showStatus();
  setText("samples", String(stats.samples));
  showRate(now);
}

window.addEventListener("resize", () => {
  for (const p of plots) p.plot.setSize({ width: Math.max(400, $("plots").clientWidth - 10), height: PLOT_HEIGHT });
});

function addBatch(b) {
  const last = cols.lastT();
  if (b.t_s.length && last !== null && b.t_s[0] < last - 1) clearData();  // the daemon restarted
  cols.append(b);
  const tEnd = cols.lastT() ?? 0;
  cols.dropBefore(tEnd - WINDOW_S);
  batches.push({ t: tEnd, n: b.stats_n, sumAbs: b.sum_abs_e_um, sumSq: b.sum_sq_e_um2, max: b.max_abs_e_um });
  while (batches.length && batches[0].t < tEnd - WINDOW_S) batches.shift();
  stats.samples += b.samples; stats.batches++; stats.gaps += b.gaps;
  if (b.t_s.length) dirty = true;   // redraw only when there is something new to show
  requestFrame();
}

function showTracking() {
  let n = 0, sumAbs = 0, sumSq = 0, max = 0;
  for (const b of batches) { n += b.n; sumAbs += b.sumAbs; sumSq += b.sumSq; max = Math.max(max, b.max); }
  setText("tracking", n ? `mean |e| ${(sumAbs / n).toFixed(3)} um, RMS ${Math.sqrt(sumSq / n).toFixed(3)} um, max |e| ${max.toFixed(3)} um (${n} samples)` : "–");
}

function showStatus() {
  const alive = lastStatus && Date.now() - lastStatusMs < NO_DAEMON_AFTER_MS;
  if (!alive) return setText("state", rig ? "no daemon" : "no daemon (no rig on the domain yet)", "state no-daemon");
  const s = lastStatus;
  setText("state", s.state_name, "state " + s.state_name);
  setText("mode", s.mode_name + (s.target === 1 ? " (open-loop voltage)" : ""));
  setText("hv", s.high_voltage ? "ON" : "off");
  setText("fault", s.fault_name);
  setText("loop", `${s.cycles} cycles at ${(1 / s.period_s).toFixed(0)} Hz, ${s.overruns} overruns, latency p50/p99/p99.9/max ${s.latency_p50_us.toFixed(0)}/${s.latency_p99_us.toFixed(0)}/${s.latency_p999_us.toFixed(0)}/${s.latency_max_us.toFixed(0)} us, compute p99 ${s.compute_p99_us.toFixed(1)} us`);
  setText("inputs", `${s.commands_accepted} commands, ${s.chunks_accepted} chunks accepted, ${s.rejects_total} refused` + (s.rejects_total ? ` (last: ${s.last_reject_reason_name}: ${s.last_reject_detail})` : ""));
}
// Without data (no daemon) nothing else asks for a frame: look twice a second.
setInterval(requestFrame, 500);

let lastCount = 0, lastCountMs = 0;
/** The received rate, over about a second, in a text frame. */
function showRate(now) {
  if (now - lastCountMs < 1000) return;
  if (lastCountMs) setText("rate", `(${((stats.samples - lastCount) * 1000 / (now - lastCountMs)).toFixed(0)}/s, ${stats.gaps} lost)`);
  lastCount = stats.samples; lastCountMs = now;
}

function send(obj) { if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(obj)); }

function selectRig(id) {
  if (id === rig) return;
  const old = [...subscriptions.keys()];
  if (old.length) send({ op: "unsubscribe", subscriptionIds: old });
  subscriptions.clear();
  rig = id;
  lastStatus = null;
  clearData();
  const subs = [];
  for (const [cid, ch] of channels) {
    if (ch.rig !== rig || !["telemetry_batch", "status", "command_reply"].includes(ch.topic)) continue;
    const sid = nextSubscription++;
    subscriptions.set(sid, cid);
    subs.push({ id: sid, channelId: cid });
  }
  send({ op: "subscribe", subscriptions: subs });
}

function updateRigPicker() {
  const rigs = [...new Set([...channels.values()].map((c) => c.rig))].sort();
  const picker = $("rig");
  if (picker.options.length !== rigs.length) {
    picker.replaceChildren(...rigs.map((r) => new Option(r, r)));
    if (rig) picker.value = rig;
  }
  if (!rig && rigs.length) selectRig(rigs.includes(defaultRig) ? defaultRig : rigs[0]);
}
$("rig").addEventListener("change", (ev) => selectRig(ev.target.value));

function onMessageData(view) {
  const sid = view.getUint32(1, true);
  const ch = channels.get(subscriptions.get(sid));
  if (!ch) return;
  const msg = JSON.parse(new TextDecoder().decode(new Uint8Array(view.buffer, 13)));
  if (ch.topic === "telemetry_batch") addBatch(msg);
  else if (ch.topic === "status") { lastStatus = msg; lastStatusMs = Date.now(); requestFrame(); }
  else if (ch.topic === "command_reply") showReply(`reply to ${msg.client_id}: ${msg.accepted ? "accepted" : msg.reason_name + ": " + msg.detail}`, msg.accepted);
}

function showReply(text, ok) {
  const el = $("reply");
  el.textContent = text;
  el.className = ok ? "" : "refused";
}

function onServiceResponse(view) {
  const callId = view.getUint32(5, true);
  const encLen = view.getUint32(9, true);
  const r = JSON.parse(new TextDecoder().decode(new Uint8Array(view.buffer, 13 + encLen)));
  showReply(`${calls.get(callId)}: ${r.accepted ? "accepted" : r.reason + ": " + r.detail}`, r.accepted);
  calls.delete(callId);
}

function onText(m) {
  if (m.op === "serverInfo") {
    allowControl = m.metadata?.allow_control === "true";
    defaultRig = m.metadata?.default_rig ?? null;
    $("controls").hidden = !allowControl;
    $("connection").textContent = `${m.name}${allowControl ? ", control allowed" : ", watch only"}`;
  } else if (m.op === "advertise") {
    for (const c of m.channels) {
      const [, r, topic] = c.topic.split("/");
      channels.set(c.id, { rig: r, topic });
    }
    updateRigPicker();
  } else if (m.op === "advertiseServices") {
    for (const s of m.services) services.set(s.name, s.id);
  } else if (m.op === "status") {
    // Presence messages name their rig: show only the one on screen.
    const about = m.id?.startsWith("presence:") ? m.id.slice("presence:".length) : null;
    if (about === null || about === rig) $("server-message").textContent = about !== null && m.level === 0 ? "" : m.message;
  } else if (m.op === "serviceCallFailure") {
    showReply(`${calls.get(m.callId) ?? "request"}: refused: ${m.message}`, false);
    calls.delete(m.callId);
  }
}

function callService(kind, request, label) {
  const id = services.get(`/${rig}/${kind}`);
  if (id === undefined) return showReply(`no ${kind} service for rig ${rig}`, false);
  const callId = nextCall++;
  calls.set(callId, label);
  const enc = new TextEncoder().encode("json");
  const payload = new TextEncoder().encode(JSON.stringify(request));
  const buf = new Uint8Array(13 + enc.length + payload.length);
  const view = new DataView(buf.buffer);
  view.setUint8(0, 2); view.setUint32(1, id, true); view.setUint32(5, callId, true); view.setUint32(9, enc.length, true);
  buf.set(enc, 13); buf.set(payload, 13 + enc.length);
  ws.send(buf);
  showReply(`${label}: sent…`, true);
}

for (const b of document.querySelectorAll("button[data-command]"))
  b.addEventListener("click", () => callService("command", { command: b.dataset.command }, b.dataset.command));
$("set-mode").addEventListener("click", () => {
  const mode = $("mode-select").value;
  callService("command", { command: "mode", argument: mode }, `mode ${mode}`);
});
$("send-reference").addEventListener("click", () => {
  const ref = $("reference-select").value;
  callService("reference", { reference: ref, blend_s: 1.0 }, `reference ${ref}`);
});

function connect() {
  ws = new WebSocket(`ws://${location.host}/`, "foxglove.websocket.v1");
  ws.binaryType = "arraybuffer";
  ws.onopen = () => { $("connection").textContent = "connected"; };
  ws.onmessage = (ev) => {
    if (typeof ev.data === "string") return onText(JSON.parse(ev.data));
    const view = new DataView(ev.data);
    const op = view.getUint8(0);
    if (op === 1) onMessageData(view);
    else if (op === 3) onServiceResponse(view);
  };
  ws.onclose = (ev) => {
    $("connection").textContent = `disconnected (${ev.reason || ev.code}); reconnecting`;
    channels.clear(); services.clear(); subscriptions.clear();
    rig = null; lastStatus = null;
    setTimeout(connect, 1000);
  };
}
connect();
