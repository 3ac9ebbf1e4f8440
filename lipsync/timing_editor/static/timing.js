// lipsync edit-timeline: the page. Plain JS on a canvas; every change goes to the server
// (PUT /api/timeline), which validates it and answers the timeline as stored.
"use strict";

const TOKEN = new URLSearchParams(location.search).get("token") || "";
const TIERS = ["words", "phones", "visemes"];
// Canvas rows (CSS pixels): the ruler, the waveform, then one row per tier.
const ROWS = { ruler: [0, 18], wave: [18, 138], words: [142, 192], phones: [196, 246], visemes: [250, 298] };
const EDGE_PX = 5;          // how close to a boundary a press grabs it
const PREFETCH = 12;        // frames requested ahead of the playhead
const MAX_INFLIGHT = 3;     // frame requests at once (the server renders them on 2 cores)
const COLORS = { words: "#dbe9f6", phones: "#e6f2dd", visemes: "#f7e7cf", sel: "#ffd54f" };

const S = window.lipsyncTiming = {
  info: null, doc: null, peaks: null, version: 0,
  t0: 0, pxPerS: 100, cursor: 0, sel: null, edge: null, loopSel: null,
  undo: [], redo: [], busy: false, ready: false, playing: false,
  frames: new Map(), inflight: 0, wanted: new Set(), shownFrame: -1, shownVersion: -1,
  frameRequests: 0, readyMs: null, lastError: null, saved: {},
};
const $ = (id) => document.getElementById(id);
const canvas = $("timeline"), ctx = canvas.getContext("2d"), audio = $("audio");

function api(path, opts = {}) {
  const headers = Object.assign({ "X-Lipsync-Token": TOKEN }, opts.headers || {});
  return fetch(path, Object.assign({}, opts, { headers }));
}
async function apiJson(path, opts) {
  const r = await api(path, opts);
  const body = await r.json().catch(() => ({ error: `HTTP ${r.status}` }));
  if (!r.ok) throw new Error(body.error || `HTTP ${r.status}`);
  return body;
}
function say(text, error = false) {
  const m = $("message");
  m.textContent = text;
  m.className = error ? "error" : "";
  if (error) S.lastError = text;
}

// ---------------------------------------------------------------- time and geometry
const fps = () => S.info.fps;
const snap = (t) => Math.round(t * fps()) / fps();
const frameOf = (t) => Math.max(0, Math.min(S.info.frames - 1, Math.floor(t * fps() + 1e-9)));
const width = () => canvas.clientWidth;
S.xOf = (t) => (t - S.t0) * S.pxPerS;
S.tOf = (x) => S.t0 + x / S.pxPerS;
S.rowY = (name) => (ROWS[name][0] + ROWS[name][1]) / 2;
function rowAt(y) {
  for (const [name, [a, b]] of Object.entries(ROWS)) if (y >= a && y < b) return name;
  return null;
}
function clampView() {
  const span = width() / S.pxPerS;
  S.t0 = Math.max(0, Math.min(S.t0, Math.max(0, S.info.duration - span)));
  $("scroll").value = S.info.duration > span ? Math.round(1000 * S.t0 / (S.info.duration - span)) : 0;
}
function zoom(factor, around) {
  const t = around === undefined ? S.cursor : around, x = S.xOf(t);
  const fit = width() / S.info.duration;
  S.pxPerS = Math.max(fit, Math.min(4000, S.pxPerS * factor));
  S.t0 = t - x / S.pxPerS;
  clampView();
  draw();
}
function fitView() { S.pxPerS = width() / S.info.duration; S.t0 = 0; clampView(); draw(); }

// ---------------------------------------------------------------- drawing
function draw() {
  const dpr = window.devicePixelRatio || 1, w = width(), h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr)) { canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr); }
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  drawRuler(w); drawWave(w);
  for (const tier of TIERS) drawTier(tier, w);
  if (S.loopSel) {
    const [a, b] = S.loopSel;
    ctx.fillStyle = "rgba(70,130,220,0.18)";
    ctx.fillRect(S.xOf(a), ROWS.wave[0], S.xOf(b) - S.xOf(a), ROWS.visemes[1] - ROWS.wave[0]);
  }
  const cx = S.xOf(S.cursor);
  ctx.strokeStyle = "#d22"; ctx.lineWidth = 1.5;
  ctx.beginPath(); ctx.moveTo(cx, 0); ctx.lineTo(cx, h); ctx.stroke();
  $("clock").textContent = `${S.cursor.toFixed(3)} s · frame ${frameOf(S.cursor)} @ ${fps()} fps`;
}
function drawRuler(w) {
  ctx.fillStyle = "#eee"; ctx.fillRect(0, 0, w, ROWS.ruler[1]);
  const steps = [0.04, 0.1, 0.2, 0.5, 1, 2, 5, 10, 30, 60, 300];
  const step = steps.find((s) => s * S.pxPerS >= 60) || 600;
  ctx.fillStyle = "#555"; ctx.font = "11px sans-serif"; ctx.textBaseline = "middle";
  for (let t = Math.ceil(S.t0 / step) * step; S.xOf(t) < w; t += step) {
    const x = S.xOf(t);
    ctx.fillRect(x, 10, 1, 8);
    ctx.fillText(t.toFixed(step < 1 ? 2 : 0) + "s", x + 3, 8);
  }
}
function drawWave(w) {
  const [top, bottom] = ROWS.wave, mid = (top + bottom) / 2, half = (bottom - top) / 2 - 2;
  ctx.fillStyle = "#fafafa"; ctx.fillRect(0, top, w, bottom - top);
  const p = S.peaks;
  if (!p) return;
  ctx.fillStyle = "#4a6b82";
  for (let x = 0; x < w; x++) {
    const i0 = Math.floor(S.tOf(x) * p.rate), i1 = Math.max(i0 + 1, Math.floor(S.tOf(x + 1) * p.rate));
    if (i0 >= p.min.length) break;
    let lo = 127, hi = -127;
    for (let i = Math.max(0, i0); i < Math.min(i1, p.min.length); i++) { lo = Math.min(lo, p.min[i]); hi = Math.max(hi, p.max[i]); }
    if (hi < lo) continue;
    ctx.fillRect(x, mid - hi / 127 * half, 1, Math.max(1, (hi - lo) / 127 * half));
  }
}
function drawTier(tier, w) {
  const [top, bottom] = ROWS[tier];
  ctx.fillStyle = "#f7f7f7"; ctx.fillRect(0, top, w, bottom - top);
  ctx.font = "12px sans-serif"; ctx.textBaseline = "middle"; ctx.textAlign = "center";
  const segs = S.doc[tier];
  segs.forEach((s, i) => {
    const x0 = S.xOf(s.start), x1 = S.xOf(s.end);
    if (x1 < 0 || x0 > w) return;
    const selected = S.sel && S.sel.tier === tier && S.sel.index === i;
    const rest = tier === "visemes" && s.label === S.info.rest;
    ctx.fillStyle = selected ? COLORS.sel : rest ? "#eee" : COLORS[tier];
    ctx.fillRect(x0, top + 2, x1 - x0, bottom - top - 4);
    ctx.fillStyle = "#888"; ctx.fillRect(x0, top, 1, bottom - top); ctx.fillRect(x1 - 1, top, 1, bottom - top);
    if (x1 - x0 > 8) {
      ctx.fillStyle = "#222";
      ctx.save(); ctx.beginPath(); ctx.rect(x0, top, x1 - x0, bottom - top); ctx.clip();
      ctx.fillText(s.label, (x0 + x1) / 2, (top + bottom) / 2); ctx.restore();
    }
  });
  if (S.edge && S.edge.tier === tier) {
    ctx.fillStyle = "#d80"; ctx.fillRect(S.xOf(S.edge.t) - 1.5, top, 3, bottom - top);
  }
  ctx.textAlign = "left"; ctx.fillStyle = "#999"; ctx.fillText(tier, 4, top + 9);
}

// ---------------------------------------------------------------- the mouth
function frameUrl(i) { return `/api/frame?t=${(i / fps()).toFixed(6)}&token=${encodeURIComponent(TOKEN)}`; }
function want(i) {
  const key = `${S.version}:${i}`;
  if (S.frames.has(key) || S.wanted.has(key)) return;
  S.wanted.add(key);
  pump();
}
function pump() {
  while (S.inflight < MAX_INFLIGHT && S.wanted.size) {
    const key = S.wanted.values().next().value;
    S.wanted.delete(key);
    const [version, i] = key.split(":").map(Number);
    if (version !== S.version) continue;
    S.inflight++; S.frameRequests++;
    api(frameUrl(i)).then((r) => (r.ok ? r.blob() : Promise.reject(new Error(`frame ${i}: HTTP ${r.status}`))))
      .then((blob) => {
        if (version === S.version) { S.frames.set(key, { url: URL.createObjectURL(blob), blob }); showMouth(); }
      })
      .catch((e) => say(String(e.message || e), true))
      .finally(() => { S.inflight--; pump(); });
  }
}
function showMouth() {
  const i = frameOf(S.cursor), got = S.frames.get(`${S.version}:${i}`);
  if (got) {
    if (S.shownFrame !== i || S.shownVersion !== S.version) {
      $("mouth").src = got.url; S.shownFrame = i; S.shownVersion = S.version; S.shownBlob = got.blob;
      $("mouth").dataset.frame = i; $("mouth").dataset.version = S.version;
    }
  } else want(i);
  if (S.playing) for (let k = 1; k <= PREFETCH && i + k < S.info.frames; k++) want(i + k);
}
function newVersion(doc) {
  S.doc = doc; S.version++;
  for (const f of S.frames.values()) URL.revokeObjectURL(f.url);
  S.frames.clear(); S.wanted.clear(); S.shownFrame = -1;
  draw(); showMouth();
}

// ---------------------------------------------------------------- edits (all through the server)
const clone = (doc) => JSON.parse(JSON.stringify(doc));
async function commit(next, opts = {}) {
  if (S.busy) { say("the previous change is still being stored: try again", true); draw(); return false; }
  S.busy = true;
  const before = S.doc;
  try {
    const stored = opts.retype
      ? await apiJson("/api/retype", { method: "POST", body: JSON.stringify(opts.retype) })
      : await apiJson("/api/timeline", { method: "PUT", body: JSON.stringify(next) });
    if (!opts.history) { S.undo.push(before); S.redo = []; }
    newVersion(stored);
    say(opts.what || "changed");
    return true;
  } catch (e) {
    say(e.message, true);
    draw();
    return false;
  } finally {
    S.busy = false;
    updateButtons();
  }
}
// A changed word or phone tier: the visemes are derived again from the phones.
const derived = (doc) => ({ words: doc.words, phones: doc.phones, visemes: null });

// Every segment end or start at time `from` in `tiers` moves to `to`, if no segment of
// them then lasts under a frame or overlaps its neighbour.
function moveBoundary(doc, tiers, from, to) {
  const eps = 1e-6, f = 1 / fps(), next = clone(doc);
  if (to < -eps || to > S.info.duration + eps) return null;
  for (const tier of tiers) {
    const segs = next[tier];
    for (let i = 0; i < segs.length; i++) {
      const s = segs[i];
      let moved = false;
      if (Math.abs(s.start - from) < eps) { s.start = to; moved = true; }
      if (Math.abs(s.end - from) < eps) { s.end = to; moved = true; }
      // only what moved is checked: the last rest may be shorter than a frame (the recording's end)
      if (moved && (s.end - s.start < f - eps || (i && s.start < segs[i - 1].end - eps) ||
                    (i + 1 < segs.length && s.end > segs[i + 1].start + eps && Math.abs(segs[i + 1].start - from) >= eps)))
        return null;
    }
  }
  return next;
}
// The tiers a boundary of `tier` carries along: a word edge takes the phone edge under it.
const carried = (tier) => (tier === "words" ? ["words", "phones"] : [tier]);
// Furthest legal position from `from` towards `to` (frame by frame).
function legalMove(doc, tier, from, to) {
  const f = 1 / fps(), dir = Math.sign(to - from);
  let best = null, bestT = from;
  for (let t = from + dir * f; dir && (dir > 0 ? t <= to + 1e-9 : t >= to - 1e-9); t += dir * f) {
    const moved = moveBoundary(doc, carried(tier), from, snap(t));
    if (!moved) break;
    best = moved; bestT = snap(t);
  }
  return best ? { doc: best, t: bestT } : null;
}
function payload(doc, tier) { return tier === "visemes" ? clone(doc) : derived(doc); }

async function nudge(frames) {
  if (!S.edge) { setCursor(S.cursor + frames / fps()); return; }
  const { tier, t } = S.edge;
  const r = legalMove(S.doc, tier, t, snap(t + frames / fps()));
  if (!r) { say("the boundary cannot move further (a segment keeps at least one frame)", true); return; }
  if (await commit(payload(r.doc, tier), { what: `moved a ${tier} boundary to ${r.t.toFixed(3)} s` })) S.edge = { tier, t: r.t };
  draw();
}
async function split() {
  if (!S.sel) return say("select a segment first", true);
  const { tier, index } = S.sel, s = S.doc[tier][index], c = snap(S.cursor);
  if (!(c > s.start + 1e-9 && c < s.end - 1e-9)) return say("put the cursor inside the selected segment (on a frame) to split it", true);
  const next = clone(S.doc);
  next[tier].splice(index, 1, { start: s.start, end: c, label: s.label }, { start: c, end: s.end, label: s.label });
  await commit(payload(next, tier), { what: `split ${tier} ${JSON.stringify(s.label)} at ${c.toFixed(3)} s` });
}
async function merge() {
  if (!S.sel) return say("select a segment first", true);
  const { tier, index } = S.sel, segs = S.doc[tier];
  if (index + 1 >= segs.length) return say("the last segment has no next one to merge with", true);
  const a = segs[index], b = segs[index + 1], next = clone(S.doc);
  const label = tier === "words" ? `${a.label}-${b.label}` : a.label;
  next[tier].splice(index, 2, { start: a.start, end: b.end, label });
  await commit(payload(next, tier), { what: `merged ${tier} ${index} and ${index + 1}` });
}
async function makeRest() {
  if (!S.sel) return say("select a segment first", true);
  const { tier, index } = S.sel, next = clone(S.doc);
  if (tier === "visemes") next.visemes[index].label = S.info.rest;
  else next[tier].splice(index, 1);  // a gap in words or phones is silence
  S.sel = null;
  await commit(payload(next, tier), { what: `made a rest in ${tier}` });
}
async function applyLabel() {
  if (!S.sel) return;
  const { tier, index } = S.sel;
  const label = tier === "visemes" ? $("viseme-choice").value : $("label").value.trim();
  if (tier === "words") {
    await commit(null, { retype: { index, label }, what: `retyped word ${index} as ${JSON.stringify(label)}` });
  } else {
    const next = clone(S.doc);
    next[tier][index].label = label;
    await commit(payload(next, tier), { what: `${tier} ${index} is now ${label}` });
  }
  select(tier, index);
}
async function undo() {
  if (!S.undo.length || S.busy) return;
  const prev = S.undo.pop(), cur = S.doc;
  if (await commit(prev, { history: true, what: "undone" })) S.redo.push(cur); else S.undo.push(prev);
}
async function redo() {
  if (!S.redo.length || S.busy) return;
  const next = S.redo.pop(), cur = S.doc;
  if (await commit(next, { history: true, what: "redone" })) S.undo.push(cur); else S.redo.push(next);
}
function updateButtons() {
  $("undo").disabled = !S.undo.length; $("redo").disabled = !S.redo.length;
}

// ---------------------------------------------------------------- selection, cursor, playback
function select(tier, index) {
  S.sel = tier ? { tier, index } : null;
  const label = $("label"), choice = $("viseme-choice"), apply = $("apply");
  if (!S.sel || !S.doc[tier][index]) {
    S.sel = null; label.disabled = apply.disabled = true; label.value = ""; choice.hidden = true;
    $("selection").textContent = "click a word, phone or viseme; drag a boundary";
  } else {
    const s = S.doc[tier][index];
    $("selection").textContent = `${tier} ${index}: ${JSON.stringify(s.label)} ${s.start.toFixed(3)}–${s.end.toFixed(3)} s`;
    apply.disabled = false;
    choice.hidden = tier !== "visemes"; label.hidden = tier === "visemes";
    label.disabled = false; label.value = s.label; choice.value = s.label;
  }
  draw();
}
function setCursor(t, fromAudio = false) {
  S.cursor = Math.max(0, Math.min(S.info.duration, t));
  if (!fromAudio && !S.playing) audio.currentTime = S.cursor;
  const x = S.xOf(S.cursor);
  if (x < 0 || x > width()) { S.t0 = S.cursor - 0.1 * width() / S.pxPerS; clampView(); }
  draw(); showMouth();
}
async function play() {
  if (S.playing) { audio.pause(); return; }
  if (S.loopSel && $("loop").checked && (S.cursor < S.loopSel[0] || S.cursor >= S.loopSel[1])) S.cursor = S.loopSel[0];
  // a seek before the audio's metadata has loaded is dropped: wait for it
  if (audio.readyState < 1) await new Promise((resolve) => audio.addEventListener("loadedmetadata", resolve, { once: true }));
  audio.currentTime = S.cursor;
  audio.play().catch((e) => say(`cannot play: ${e.message}`, true));
}
audio.addEventListener("play", () => { S.playing = true; $("play").textContent = "❚❚ pause"; tick(); });
audio.addEventListener("pause", () => { S.playing = false; $("play").textContent = "▶ play"; });
function tick() {
  if (!S.playing) return;
  let t = audio.currentTime;
  if (S.loopSel && $("loop").checked && t >= S.loopSel[1]) { audio.currentTime = t = S.loopSel[0]; }
  setCursor(t, true);
  requestAnimationFrame(tick);
}

// ---------------------------------------------------------------- mouse
let drag = null;
function edgeAt(tier, x) {
  let best = null;
  for (const s of S.doc[tier]) for (const t of [s.start, s.end]) {
    const d = Math.abs(S.xOf(t) - x);
    if (d <= EDGE_PX && (!best || d < best.d)) best = { t, d };
  }
  return best;
}
canvas.addEventListener("pointerdown", (ev) => {
  const r = canvas.getBoundingClientRect(), x = ev.clientX - r.left, y = ev.clientY - r.top, row = rowAt(y);
  canvas.setPointerCapture(ev.pointerId);
  if (TIERS.includes(row)) {
    const e = edgeAt(row, x);
    if (e) { S.edge = { tier: row, t: e.t }; drag = { kind: "edge", tier: row, from: e.t, preview: null }; draw(); return; }
    const t = S.tOf(x), i = S.doc[row].findIndex((s) => s.start <= t && t < s.end);
    S.edge = null;
    select(i >= 0 ? row : null, i);
    setCursor(t);
    return;
  }
  if (row === "wave" && ev.shiftKey) { drag = { kind: "loop", from: snap(S.tOf(x)) }; S.loopSel = null; return; }
  drag = { kind: "scrub" };
  S.edge = null;
  setCursor(S.tOf(x));
});
canvas.addEventListener("pointermove", (ev) => {
  if (!drag) return;
  const r = canvas.getBoundingClientRect(), x = ev.clientX - r.left, t = S.tOf(x);
  if (drag.kind === "scrub") setCursor(t);
  else if (drag.kind === "loop") { const b = snap(t); S.loopSel = [Math.min(drag.from, b), Math.max(drag.from, b)]; draw(); }
  else if (drag.kind === "edge") {
    const moved = legalMove(drag.doc0 || (drag.doc0 = S.doc), drag.tier, drag.from, snap(t));
    drag.preview = moved;
    S.doc = moved ? moved.doc : drag.doc0;
    S.edge = { tier: drag.tier, t: moved ? moved.t : drag.from };
    draw();
  }
});
canvas.addEventListener("pointerup", async () => {
  const d = drag;
  drag = null;
  if (!d || d.kind !== "edge" || !d.preview) { if (d && d.kind === "loop" && S.loopSel && S.loopSel[1] <= S.loopSel[0]) S.loopSel = null; return; }
  S.doc = d.doc0;  // the stored doc until the server answers
  if (await commit(payload(d.preview.doc, d.tier), { what: `moved a ${d.tier} boundary ${d.from.toFixed(3)} → ${d.preview.t.toFixed(3)} s` }))
    S.edge = { tier: d.tier, t: d.preview.t };
  draw();
});
canvas.addEventListener("wheel", (ev) => {
  ev.preventDefault();
  const r = canvas.getBoundingClientRect();
  if (ev.ctrlKey) zoom(ev.deltaY < 0 ? 1.25 : 0.8, S.tOf(ev.clientX - r.left));
  else { S.t0 += (ev.deltaX || ev.deltaY) / S.pxPerS; clampView(); draw(); }
}, { passive: false });

// ---------------------------------------------------------------- keys and buttons
document.addEventListener("keydown", (ev) => {
  if (ev.target.tagName === "INPUT" && ev.target.type === "text") {
    if (ev.key === "Enter") { ev.preventDefault(); applyLabel(); }
    return;
  }
  const k = ev.key;
  if (k === " ") { ev.preventDefault(); play(); }
  else if (k === "ArrowLeft" || k === "ArrowRight") { ev.preventDefault(); nudge(k === "ArrowLeft" ? -1 : 1); }
  else if ((ev.ctrlKey || ev.metaKey) && k.toLowerCase() === "z") { ev.preventDefault(); ev.shiftKey ? redo() : undo(); }
  else if ((ev.ctrlKey || ev.metaKey) && k.toLowerCase() === "y") { ev.preventDefault(); redo(); }
  else if (k === "s" || k === "S") split();
  else if (k === "m" || k === "M") merge();
  else if (k === "Delete" || k === "Backspace") makeRest();
  else if (k === "+" || k === "=") zoom(1.5);
  else if (k === "-") zoom(1 / 1.5);
  else if (k === "Home") setCursor(0);
  else if (k === "End") setCursor(S.info.duration);
});
async function save() {
  const fmt = $("format").value;
  try {
    const r = await apiJson(`/api/save?format=${fmt}`, { method: "POST" });
    S.saved[fmt] = r.path;
    say(`saved ${r.path}`);
  } catch (e) { say(`not saved: ${e.message}`, true); }
}
async function render() {
  say("rendering…");
  try { const r = await apiJson("/api/render", { method: "POST" }); S.saved.mp4 = r.path; say(`rendered ${r.path}`); }
  catch (e) { say(`not rendered: ${e.message}`, true); }
}
S.save = save;
$("play").onclick = play; $("zoom-in").onclick = () => zoom(1.5); $("zoom-out").onclick = () => zoom(1 / 1.5);
$("zoom-fit").onclick = fitView; $("undo").onclick = undo; $("redo").onclick = redo;
$("split").onclick = split; $("merge").onclick = merge; $("rest").onclick = makeRest;
$("apply").onclick = applyLabel; $("save").onclick = save; $("render").onclick = render;
$("scroll").oninput = (ev) => {
  const span = width() / S.pxPerS;
  S.t0 = Math.max(0, S.info.duration - span) * ev.target.value / 1000; draw();
};
window.addEventListener("resize", () => { clampView(); draw(); });

// ---------------------------------------------------------------- start
(async function start() {
  const t0 = performance.now();
  try {
    const [info, doc, peaks] = await Promise.all([apiJson("/api/info"), apiJson("/api/timeline"), apiJson("/api/peaks")]);
    S.info = info; S.doc = doc; S.peaks = peaks;
    $("file").textContent = `${info.audio} · ${info.duration.toFixed(2)} s · ${info.fps} fps`;
    const choice = $("viseme-choice");
    for (const v of info.visemes) { const o = document.createElement("option"); o.value = o.textContent = v; choice.appendChild(o); }
    // a blob is seekable whatever the server does about Range requests
    api("/api/audio").then((r) => r.blob()).then((b) => { audio.src = URL.createObjectURL(b); })
      .catch((e) => say(`cannot load the audio: ${e.message}`, true));
    fitView(); updateButtons();
    S.version = 1;
    showMouth();
    await new Promise((resolve) => {
      const check = () => (S.shownFrame >= 0 ? resolve() : setTimeout(check, 10));
      check();
    });
    S.readyMs = performance.now() - t0;
    S.ready = true;
    document.body.dataset.ready = "1";
    say(`${doc.words.length} words, ${doc.phones.length} phones, ${doc.visemes.length} visemes`);
  } catch (e) {
    say(`cannot load: ${e.message}`, true);
  }
})();
