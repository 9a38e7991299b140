// The live page: a thin client of pvcgel serve's Foxglove WebSocket protocol
// (foxglove.websocket.v1), the same channels and services Foxglove Studio sees.
import uPlot from "/uplot/uPlot.esm.js";

const WINDOW_S = 10;          // plots and statistics cover the last 10 s of loop time
const NO_DAEMON_AFTER_MS = 2500;  // Status comes at >= 2 Hz
const $ = (id) => document.getElementById(id);

const stats = { frames: 0, samples: 0, batches: 0, gaps: 0, lag_s: null };
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
      // null (a faulted sensor) -> NaN here, null again for uPlot (withGaps).
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

/** uPlot breaks a line only at null: a column with NaN (a faulted sensor's
 *  samples) becomes an array with null there, so the plot shows a gap instead
 *  of joining across it. Columns without NaN (the usual case) pass as views. */
function withGaps(column) {
  return column.some(Number.isNaN) ? Array.from(column, (v) => (Number.isNaN(v) ? null : v)) : column;
}

const cols = new WindowColumns(2048);   // grows if a smaller --page-decimation needs more
let batches = [];             // {t, n, sumAbs, sumSq, max}
let dirty = false;

function clearData() {
  cols.clear();
  tDisplay = null;
  batches = [];
  dirty = true;
}

// The plots scroll like a strip chart. uPlot draws each plot once per batch
// (10 a second) over the visible 10 s plus LEAD_S ahead; between draws the
// canvas only moves left by whole pixels (a compositor transform, no redraw).
// In a browser without a GPU, redrawing four canvases 32 times a second cost
// ~20 % of a core, moving them costs a few %. The display runs LAG_S behind
// the newest sample, so the right edge always has data; y's axis stays put
// because a copy of it, made at each draw, covers the canvas's left edge.
const LAG_S = 0.25;           // > one batch (0.1 s) plus its jitter
const LEAD_S = 0.6;           // drawn beyond the right edge: LAG_S plus the motion until the next draw
const FRAME_MS = 1000 / 32;   // >= 30 frames/s with a margin; each frame costs CPU without a GPU
const PLOT_HEIGHT = 150;
let tRef = WINDOW_S;          // loop time at the right edge when the plots were last drawn
let tDisplay = null;          // loop time at the right edge now
let lastTickMs = 0;
let resizePending = false;

/** Runs `make` with every 2D context created opaque ({alpha: false}). uPlot has
 *  no option for it; an opaque canvas lets a software compositor copy the moving
 *  canvas instead of blending it over the page 32 times a second. */
function withOpaqueCanvases(make) {
  const getContext = HTMLCanvasElement.prototype.getContext;
  HTMLCanvasElement.prototype.getContext = function (type, attributes) {
    return getContext.call(this, type, { ...attributes, alpha: false });
  };
  try { return make(); } finally { HTMLCanvasElement.prototype.getContext = getContext; }
}

/** An opaque canvas clears to black: uPlot's clear, then the page's white. */
function fillWhite(u) {
  u.ctx.fillStyle = "#fff";
  u.ctx.fillRect(0, 0, u.ctx.canvas.width, u.ctx.canvas.height);
}

function makePlot(title, series, yLabel, keys) {
  const box = document.createElement("div");
  box.className = "plot";
  $("plots").appendChild(box);
  const p = { box, keys, pxPerS: 0, shiftPx: 0 };
  p.u = withOpaqueCanvases(() => new uPlot({
    title, width: 600, height: PLOT_HEIGHT,
    padding: [8, 8, 0, 0],   // fixed (uPlot's default follows the tick labels), so the plot area keeps its place
    scales: { x: { time: false, range: () => [tRef - WINDOW_S, tRef + LEAD_S] } },
    // Lean for software rasterising: tick labels every second and every ~30 px,
    // lines, grid and ticks 1 px wide. The time axis's name is in the caption
    // above the plots: drawn on the moving canvas it would wobble.
    axes: [{ space: 90, size: 24, grid: { width: 1 }, ticks: { width: 1 } },
      { label: yLabel, space: 30, grid: { width: 1 }, ticks: { width: 1 } }],
    series: [{ label: "t (s)" }, ...series],
    legend: { show: false },
    cursor: { show: false },
    hooks: { drawClear: [fillWhite], draw: [() => copyAxis(p)] },
  }, [[]], box));
  p.axis = document.createElement("canvas");
  p.axis.className = "y-axis";
  box.appendChild(p.axis);
  p.u.ctx.canvas.classList.add("moving");
  sizePlot(p);
  return p;
}

/** The visible part (the box) shows exactly WINDOW_S of the plot area; the
 *  canvas is LEAD_S wider, to the right. */
function sizePlot(p) {
  const visible = Math.max(400, $("plots").clientWidth - 10);
  const left = p.u.bbox.left / devicePixelRatio;
  const right = p.u.width - left - p.u.bbox.width / devicePixelRatio;
  p.sizedLeft = left;
  p.pxPerS = (visible - left) / WINDOW_S;
  p.box.style.width = `${visible}px`;
  p.u.setSize({ width: Math.round(left + p.pxPerS * (WINDOW_S + LEAD_S) + right), height: PLOT_HEIGHT });
}

/** After each draw: a copy of the y axis (left of the plot area) for the box's
 *  left edge; a y axis that widened with its labels resizes the plot at the next frame. */
function copyAxis(p) {
  if (!p.axis) return;
  if (p.u.bbox.left / devicePixelRatio !== p.sizedLeft) resizePending = true;
  const src = p.u.ctx.canvas, w = Math.round(p.u.bbox.left), h = src.height;
  if (p.axis.width !== w || p.axis.height !== h) {
    p.axis.width = w; p.axis.height = h;
    p.axis.style.width = `${w / devicePixelRatio}px`;
    p.axis.style.height = `${h / devicePixelRatio}px`;
    p.axis.style.top = `${src.getBoundingClientRect().top - p.box.getBoundingClientRect().top}px`;
  }
  p.axis.getContext("2d").drawImage(src, 0, 0, w, h, 0, 0, w, h);   // the source is opaque: every pixel replaced
}

const plots = [
  // r dashed on top of y: both show where they coincide.
  makePlot("displacement y (blue) and reference r (black, dashed), um", [{ label: "y (um)", stroke: "#06c" }, { label: "r (um)", stroke: "#222", dash: [6, 6] }], "um", ["y", "r"]),
  makePlot("tracking error e = r - y, um", [{ label: "e (um)", stroke: "#c30" }], "um", ["e"]),
  makePlot("amplifier voltage u, V", [{ label: "u (V)", stroke: "#690" }], "V", ["u"]),
  makePlot("disturbance estimate d_hat (linear-block input units)", [{ label: "d_hat", stroke: "#939" }], "d_hat", ["d"]),
];

/** The display clock: follows the wall clock, steered (rate 1 +- the error per
 *  second, at most 50 %) to stay LAG_S behind the newest sample, never past it
 *  (a stalled daemon freezes the plots); jumps at a start, restart or long stall. */
function advanceDisplay(nowMs) {
  const latest = cols.lastT();
  const dt = lastTickMs ? Math.min(0.2, (nowMs - lastTickMs) / 1000) : 0;
  lastTickMs = nowMs;
  if (latest === null) return;
  const error = latest - LAG_S - tDisplay;
  if (tDisplay === null || !(Math.abs(error) < 1)) tDisplay = latest - LAG_S;
  else tDisplay = Math.min(latest, tDisplay + dt * (1 + Math.max(-0.5, Math.min(0.5, error))));
}

/** Moves a plot's canvas so that the box's right edge shows tDisplay (whole
 *  pixels: a fractional shift would be resampled). Returns whether it moved. */
function shiftPlot(p) {
  const px = Math.round((tDisplay - tRef) * p.pxPerS);
  if (px === p.shiftPx) return false;
  p.shiftPx = px;
  p.u.ctx.canvas.style.transform = `translateX(${-px}px)`;
  return true;
}

// One animation frame every FRAME_MS (a timer, not every display refresh: in a
// browser without a GPU every frame, even one that changes nothing, costs
// about a millisecond of CPU): the plots move, are drawn again when a batch
// brought data, and text changes every 250 ms.
let frameRequested = false;
function requestFrame() {
  if (frameRequested) return;
  frameRequested = true;
  requestAnimationFrame(render);
}
setInterval(requestFrame, FRAME_MS);

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
  advanceDisplay(now);
  let changed = false;
  if (resizePending) {
    resizePending = false;
    for (const p of plots) sizePlot(p);
    dirty = true;
  }
  if (dirty && tDisplay !== null) {
    dirty = false;
    tRef = tDisplay;
    for (const p of plots) p.u.setData([cols.view("t"), ...p.keys.map((k) => withGaps(cols.view(k)))]);
    changed = true;
  }
  if (tDisplay !== null) for (const p of plots) changed = shiftPlot(p) || changed;
  stats.lag_s = tDisplay === null ? null : cols.lastT() - tDisplay;
  if (changed) stats.frames++;
  if (now - lastTextMs < TEXT_EVERY_MS) return;
  lastTextMs = now;
  showTracking();
  showStatus();
  setText("samples", String(stats.samples));
  showRate(now);
}

window.addEventListener("resize", () => { resizePending = true; });

function addBatch(b) {
  const last = cols.lastT();
  if (b.t_s.length && last !== null && b.t_s[0] < last - 1) clearData();  // the daemon restarted
  cols.append(b);
  const tEnd = cols.lastT() ?? 0;
  cols.dropBefore(tEnd - WINDOW_S - 2 * LAG_S);   // the display runs LAG_S behind
  batches.push({ t: tEnd, n: b.stats_n, sumAbs: b.sum_abs_e_um, sumSq: b.sum_sq_e_um2, max: b.max_abs_e_um });
  while (batches.length && batches[0].t < tEnd - WINDOW_S) batches.shift();
  stats.samples += b.samples; stats.batches++; stats.gaps += b.gaps;
  if (b.t_s.length) dirty = true;   // redraw only when there is something new to show
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
  else if (ch.topic === "status") { lastStatus = msg; lastStatusMs = Date.now(); }
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
