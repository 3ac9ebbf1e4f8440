// lipsync edit: plain JS, no build step. The server validates and renders; this page edits
// the bank document (the plain data of bank.yaml) and shows it.
"use strict";

const TOKEN = new URLSearchParams(location.search).get("token") || "";
const SVGNS = "http://www.w3.org/2000/svg";
// Same palette and colouring rule as lipsync.preview: by sorted base name, partners share.
const PALETTE = ["#e6194b", "#3cb44b", "#0082c8", "#f58230", "#911eb4", "#46f0f0", "#f032e6",
  "#d2f53c", "#008080", "#aa6e28", "#ffe119", "#000080", "#800000", "#808000", "#ffa0c8",
  "#6464ff", "#ff6400", "#00c896", "#bebe00", "#5a00c8"];
const UNDO_LIMIT = 200;
const DRAFT_DELAY_MS = 150;   // coalesce a burst of edits into one draft
const STATUS_EVERY_MS = 700;  // flow progress polling
const PLAY_STEP = 0.05;
// A short pause between played frames: lets the page paint and other requests finish.
const PLAY_PAUSE_MS = 15;

const S = {
  doc: null, names: [], shape: [0, 0], axis: null, current: null, selected: null,
  undo: [], redo: [], view: null, version: 0, errors: {}, playing: false,
  lastMethod: "", pendingSince: null, lastUpdateMs: null, savedAt: null, saveToPreviewMs: null,
  previewBusy: false, previewAgain: false, previewCount: 0,
};
window.lipsyncEditor = S;  // for tests and the curious

const $ = (id) => document.getElementById(id);

function api(path, options = {}) {
  options.headers = Object.assign({"X-Lipsync-Token": TOKEN}, options.headers || {});
  return fetch(path, options);
}
function imageUrl(name) {
  // <image> cannot send headers: the token goes in the query.
  return "/api/image/" + encodeURIComponent(name).replace(/%2F/g, "/") + "?token=" + encodeURIComponent(TOKEN);
}

// ---------------------------------------------------------------- features
function kindOf(f) { return Array.isArray(f) ? "line" : (f.polyline ? "polyline" : "bezier"); }
function pointsOf(f) { return Array.isArray(f) ? f : (f.polyline || f.bezier); }
function baseName(n) { return /_[lr]$/.test(n) ? n.slice(0, -2) : n; }
function partnerOf(n) {
  if (n.endsWith("_l")) return n.slice(0, -2) + "_r";
  if (n.endsWith("_r")) return n.slice(0, -2) + "_l";
  return null;
}
function lines(v) { return S.doc.visemes[v].lines; }
function featureNames() { return Object.keys(lines(S.names[0])); }
function colourMap() {
  const bases = [...new Set(featureNames().map(baseName))].sort();
  const out = {};
  bases.forEach((b, i) => { out[b] = PALETTE[i % PALETTE.length]; });
  return out;
}
const round1 = (x) => Math.round(x * 10) / 10;  // dragged points: 1/10 px is plenty

// ---------------------------------------------------------------- undo / redo
// Placing lines from the face also sets warp and symmetry: an undo step restores them too.
function snapshot() {
  return JSON.stringify({visemes: S.doc.visemes, warp: S.doc.warp, symmetry: S.doc.symmetry, axis: S.axis});
}
function restore(text) {
  const s = JSON.parse(text);
  S.doc.visemes = s.visemes;
  for (const key of ["warp", "symmetry"]) {
    if (s[key] === undefined) delete S.doc[key]; else S.doc[key] = s[key];
  }
  S.axis = s.axis === undefined ? null : s.axis;
  showSymmetry();
}
function pushUndo() {
  S.undo.push(snapshot());
  if (S.undo.length > UNDO_LIMIT) S.undo.shift();
  S.redo = [];
  updateButtons();
}
function undo() {
  if (!S.undo.length) return;
  S.redo.push(snapshot());
  restore(S.undo.pop());
  changed();
}
function redo() {
  if (!S.redo.length) return;
  S.undo.push(snapshot());
  restore(S.redo.pop());
  changed();
}
function updateButtons() {
  $("undo").disabled = !S.undo.length;
  $("redo").disabled = !S.redo.length;
}

// ---------------------------------------------------------------- drawing
function el(name, attrs, parent) {
  const e = document.createElementNS(SVGNS, name);
  for (const k in attrs) e.setAttribute(k, attrs[k]);
  if (parent) parent.appendChild(e);
  return e;
}
function shapeElement(f, attrs, parent) {
  const pts = pointsOf(f);
  const kind = kindOf(f);
  if (kind === "bezier") {
    let d = `M ${pts[0][0]} ${pts[0][1]}`;
    for (let i = 1; i + 2 < pts.length; i += 3)
      d += ` C ${pts[i][0]} ${pts[i][1]} ${pts[i + 1][0]} ${pts[i + 1][1]} ${pts[i + 2][0]} ${pts[i + 2][1]}`;
    return el("path", Object.assign({d}, attrs), parent);
  }
  return el("polyline", Object.assign({points: pts.map((p) => p.join(",")).join(" ")}, attrs), parent);
}
function unitsPerPixel() {
  // The image is fitted whole (preserveAspectRatio "meet"): the tighter direction rules.
  const svg = $("canvas");
  return Math.max(S.view.w / Math.max(1, svg.clientWidth), S.view.h / Math.max(1, svg.clientHeight));
}
function drawCanvas() {
  const g = $("canvas-lines");
  g.textContent = "";
  const colours = colourMap();
  const u = unitsPerPixel();
  const v = S.current;
  for (const [name, f] of Object.entries(lines(v))) {
    const colour = colours[baseName(name)];
    const cls = "feature" + (name === S.selected ? " selected" : "") + (S.errors[name] ? " error" : "");
    const shape = shapeElement(f, {class: cls, stroke: colour, "data-feature": name}, g);
    shape.addEventListener("pointerdown", (e) => { select(name); e.stopPropagation(); });
    const pts = pointsOf(f);
    if (kindOf(f) === "bezier")
      el("polyline", {class: "control", points: pts.map((p) => p.join(",")).join(" ")}, g);
    pts.forEach((p, k) => {
      const h = el("circle", {class: "handle", cx: p[0], cy: p[1], r: (k === 0 ? 5 : 4) * u, fill: colour,
        "data-feature": name, "data-k": k}, g);
      h.addEventListener("pointerdown", (e) => startDrag(e, name, k));
    });
    el("title", {}, shape).textContent = name;
    // Names only for the selected line and its partner: all 40 at once hide the mouth.
    if (name !== S.selected && name !== partnerOf(S.selected || "")) continue;
    const mid = pts[Math.floor((pts.length - 1) / 2)], nxt = pts[Math.floor((pts.length - 1) / 2) + 1];
    // Left partners are labelled to the left, so the two names of a pair do not overlap.
    const left = name.endsWith("_l");
    const label = el("text", {class: "label", x: (mid[0] + nxt[0]) / 2 + (left ? -6 : 6) * u,
      y: (mid[1] + nxt[1]) / 2 - 6 * u, fill: colour, "font-size": 12 * u, "stroke-width": 2.5 * u,
      "text-anchor": left ? "end" : "start"}, g);
    label.textContent = name;
  }
}
function drawThumb(v) {
  const svg = document.querySelector(`.thumb[data-viseme="${CSS.escape(v)}"] svg`);
  if (!svg) return;
  const g = svg.querySelector("g");
  g.textContent = "";
  const colours = colourMap();
  for (const [name, f] of Object.entries(lines(v)))
    shapeElement(f, {class: "feature", stroke: colours[baseName(name)]}, g);
}
function buildThumbs() {
  const box = $("thumbs");
  box.textContent = "";
  const [h, w] = S.shape;
  for (const v of S.names) {
    const div = document.createElement("div");
    div.className = "thumb";
    div.dataset.viseme = v;
    const svg = el("svg", {viewBox: `0 0 ${w} ${h}`}, div);
    el("image", {href: imageUrl(S.doc.visemes[v].image), x: 0, y: 0, width: w, height: h}, svg);
    el("g", {}, svg);
    const cap = document.createElement("div");
    cap.className = "cap";
    cap.textContent = v + (v === S.doc.rest ? " (rest)" : "");
    div.appendChild(cap);
    div.addEventListener("click", () => showViseme(v));
    box.appendChild(div);
  }
}
function drawFeatureList() {
  const ul = $("features");
  ul.textContent = "";
  for (const name of featureNames()) {
    const li = document.createElement("li");
    li.dataset.feature = name;
    if (name === S.selected) li.className = "selected";
    const n = document.createElement("span");
    n.textContent = name;
    const k = document.createElement("span");
    k.className = "kind";
    k.textContent = kindOf(lines(S.current)[name] || lines(S.names[0])[name]);
    li.append(n, k);
    if (S.errors[name]) {
      const e = document.createElement("span");
      e.className = "error";
      e.textContent = S.errors[name];
      li.appendChild(e);
    }
    li.addEventListener("click", () => select(name));
    ul.appendChild(li);
    if (name === S.selected) li.scrollIntoView({block: "nearest"});
  }
}
function redraw() {
  drawCanvas();
  S.names.forEach(drawThumb);
  drawFeatureList();
  document.querySelectorAll(".thumb").forEach((t) => t.classList.toggle("current", t.dataset.viseme === S.current));
  $("viseme-name").textContent = S.current;
  updateButtons();
}
function applyView() {
  const v = S.view;
  $("canvas").setAttribute("viewBox", `${v.x} ${v.y} ${v.w} ${v.h}`);
  drawCanvas();
}

// ---------------------------------------------------------------- interaction
function showViseme(v) {
  S.current = v;
  $("canvas-image").setAttribute("href", imageUrl(S.doc.visemes[v].image));
  if (v !== $("to").value && v !== $("from").value) { $("to").value = v; refreshPreview(); }
  redraw();
}
function select(name) {
  S.selected = name;
  $("line-name").value = name;
  redraw();
}
function svgPoint(e) {
  const svg = $("canvas");
  const p = svg.createSVGPoint();
  p.x = e.clientX; p.y = e.clientY;
  return p.matrixTransform(svg.getScreenCTM().inverse());
}
function selfMirror(v, name, k) {
  // An unpaired feature across the axis (a brow line, a chin curve) is its own mirror image
  // run backwards: point k mirrors point N-1-k when they sit mirrored now (within 1 px).
  if (!S.doc.symmetry || S.axis === null || partnerOf(name)) return -1;
  const pts = pointsOf(lines(v)[name]), j = pts.length - 1 - k;
  if (j === k) return -1;
  const near = Math.abs(2 * S.axis - pts[k][0] - pts[j][0]) < 1 && Math.abs(pts[k][1] - pts[j][1]) < 1;
  return near ? j : -1;
}
function movePoint(v, name, k, x, y, mirror = -1) {
  const pts = pointsOf(lines(v)[name]);
  pts[k] = [x, y];
  if (mirror >= 0) pts[mirror] = [round1(2 * S.axis - x), y];
  const partner = partnerOf(name);
  if (S.doc.symmetry && S.axis !== null && partner && lines(v)[partner]) {
    const pp = pointsOf(lines(v)[partner]);
    if (k < pp.length) pp[k] = [round1(2 * S.axis - x), y];
  }
}
function startDrag(e, name, k) {
  e.stopPropagation();
  e.preventDefault();
  // Listen on the window: redraws replace the handle element under the pointer.
  const start = svgPoint(e);
  select(name);
  pushUndo();
  const p0 = pointsOf(lines(S.current)[name])[k].slice();
  const mirror = selfMirror(S.current, name, k);
  const move = (ev) => {
    const p = svgPoint(ev);
    movePoint(S.current, name, k, round1(p0[0] + p.x - start.x), round1(p0[1] + p.y - start.y), mirror);
    drawCanvas();
  };
  const up = () => {
    window.removeEventListener("pointermove", move);
    window.removeEventListener("pointerup", up);
    window.removeEventListener("pointercancel", up);
    changed();
  };
  window.addEventListener("pointermove", move);
  window.addEventListener("pointerup", up);
  window.addEventListener("pointercancel", up);
}
function setupPanZoom() {
  const svg = $("canvas");
  svg.addEventListener("pointerdown", (e) => {
    if (e.target !== svg && e.target.id !== "canvas-image") return;
    svg.setPointerCapture(e.pointerId);
    svg.classList.add("panning");
    const u = unitsPerPixel(), x0 = e.clientX, y0 = e.clientY, vx = S.view.x, vy = S.view.y;
    const move = (ev) => { S.view.x = vx - (ev.clientX - x0) * u; S.view.y = vy - (ev.clientY - y0) * u; applyView(); };
    const up = () => { svg.classList.remove("panning"); svg.removeEventListener("pointermove", move); svg.removeEventListener("pointerup", up); };
    svg.addEventListener("pointermove", move);
    svg.addEventListener("pointerup", up);
  });
  svg.addEventListener("wheel", (e) => {
    e.preventDefault();
    zoom(e.deltaY < 0 ? 1 / 1.2 : 1.2, svgPoint(e));
  }, {passive: false});
}
function zoom(f, about) {
  const v = S.view;
  const c = about || {x: v.x + v.w / 2, y: v.y + v.h / 2};
  v.x = c.x - (c.x - v.x) * f; v.y = c.y - (c.y - v.y) * f;
  v.w *= f; v.h *= f;
  applyView();
}
function fit() {
  const [h, w] = S.shape;
  S.view = {x: 0, y: 0, w, h};
  applyView();
}
function errorOut(text) {
  const m = $("message");
  m.textContent = text;
  m.className = "bad";
}
function addLine() {
  const name = $("line-name").value.trim();
  if (!/^[A-Za-z0-9_.+-]{1,64}$/.test(name)) return errorOut("line names use letters, digits and _ . + - only");
  if (lines(S.names[0])[name] !== undefined) return errorOut(`there is a line ${name} already`);
  const [h, w] = S.shape;
  const axis = S.axis !== null ? S.axis : (w - 1) / 2;
  const partner = S.doc.symmetry ? partnerOf(name) : null;
  const kind = $("new-kind").value;
  // A new feature runs from a to b across the middle of the picture; curves bow upwards.
  const make = (a, b, y) => {
    const lift = round1(h / 32);
    if (kind === "bezier")
      return {bezier: [[a, y], [round1(a + (b - a) / 3), y - lift], [round1(a + 2 * (b - a) / 3), y - lift], [b, y]]};
    if (kind === "polyline") return {polyline: [[a, y], [round1((a + b) / 2), y - lift], [b, y]]};
    return [[a, y], [b, y]];
  };
  pushUndo();
  for (const v of S.names) {
    const y = round1(h / 2);
    if (partner) {
      const side = name.endsWith("_l") ? -1 : 1;
      const a = round1(axis + side * w / 8), b = round1(axis + side * w / 16);
      lines(v)[name] = make(a, b, y);
      if (lines(v)[partner] === undefined) lines(v)[partner] = make(round1(2 * axis - a), round1(2 * axis - b), y);
    } else {
      lines(v)[name] = make(round1(axis - w / 16), round1(axis + w / 16), y);
    }
  }
  S.selected = name;
  changed();
}
function renameLine() {
  const old = S.selected, name = $("line-name").value.trim();
  if (!old) return errorOut("select a line first");
  if (!/^[A-Za-z0-9_.+-]{1,64}$/.test(name)) return errorOut("line names use letters, digits and _ . + - only");
  if (name === old) return;
  if (lines(S.names[0])[name] !== undefined) return errorOut(`there is a line ${name} already`);
  const renames = [[old, name]];
  const po = partnerOf(old), pn = partnerOf(name);
  if (S.doc.symmetry && po && pn && lines(S.names[0])[po] !== undefined && lines(S.names[0])[pn] === undefined)
    renames.push([po, pn]);
  pushUndo();
  for (const v of S.names) {
    // Rebuild the mapping to keep the line's place in the file.
    const out = {};
    for (const [n, f] of Object.entries(lines(v))) {
      const hit = renames.find((r) => r[0] === n);
      out[hit ? hit[1] : n] = f;
    }
    S.doc.visemes[v].lines = out;
  }
  S.selected = name;
  changed();
}
function deleteLine() {
  const name = S.selected;
  if (!name) return errorOut("select a line first");
  const partner = S.doc.symmetry ? partnerOf(name) : null;
  pushUndo();
  for (const v of S.names) {
    delete lines(v)[name];
    if (partner) delete lines(v)[partner];
  }
  S.selected = null;
  changed();
}
function copyLines() {
  const from = $("copy-from").value;
  if (!from || from === S.current) return;
  pushUndo();
  S.doc.visemes[S.current].lines = JSON.parse(JSON.stringify(lines(from)));
  changed();
}

async function placeFromFace() {
  const all = $("face-scope").value === "all";
  const m = $("message");
  m.textContent = "placing lines from the face...";
  m.className = "";
  const r = await api("/api/face", {method: "POST", headers: {"Content-Type": "application/json"},
    body: JSON.stringify({doc: S.doc, visemes: all ? "all" : [S.current]})});
  const body = await r.json();
  if (!body.ok) {
    m.textContent = "not placed: " + body.error.message.replace(/^.*?bank\.yaml(:\d+)?: /, "");
    m.className = "bad";
    return;
  }
  pushUndo();
  S.doc = body.doc;
  S.axis = body.axis;
  showSymmetry();
  const borrowed = Object.entries(body.sources).filter(([, src]) => src !== "face");
  m.textContent = `lines placed from the face on ${Object.keys(body.sources).join(", ")}` +
    (borrowed.length ? "; " + borrowed.map(([v, src]) => `${v}: ${src}`).join("; ") : "");
  m.className = borrowed.length ? "bad" : "ok";
  S.selected = null;
  changed();
}
function showSymmetry() {
  $("symmetry-note").textContent = S.doc.symmetry && S.axis !== null ?
    `Symmetry is on: moving an _l line moves its _r partner (axis x = ${S.axis}).` : "";
}

// ---------------------------------------------------------------- server
let draftTimer = null;
function changed() {
  redraw();
  clearTimeout(draftTimer);
  draftTimer = setTimeout(sendDraft, DRAFT_DELAY_MS);
}
function showErrors(err) {
  S.errors = {};
  $("general-error").textContent = "";
  if (err) {
    const where = err.viseme ? `${err.viseme}: ` : "";
    const short = err.message.replace(/^.*?bank\.yaml(:\d+)?: /, "");
    if (err.feature) S.errors[err.feature] = where + short;
    else $("general-error").textContent = short;
  }
  redraw();
}
async function sendDraft() {
  S.pendingSince = performance.now();
  const r = await api("/api/draft", {method: "POST", headers: {"Content-Type": "application/json"},
    body: JSON.stringify({doc: S.doc, pair: [$("from").value, $("to").value]})});
  const body = await r.json();
  if (body.ok) {
    S.version = body.version;
    showErrors(null);
    refreshPreview();
  } else {
    showErrors(body.error);
    S.pendingSince = null;
  }
}
async function save() {
  clearTimeout(draftTimer);
  const t0 = performance.now();
  const r = await api("/api/save", {method: "POST", headers: {"Content-Type": "application/json"},
    body: JSON.stringify({doc: S.doc})});
  const body = await r.json();
  const m = $("message");
  if (body.ok) {
    S.version = body.version;
    S.savedAt = t0;
    S.pendingSince = t0;
    showErrors(null);
    m.textContent = "saved " + body.path;
    m.className = "ok";
    refreshPreview();
  } else {
    showErrors(body.error);
    m.textContent = "not saved: " + body.error.message.replace(/^.*?bank\.yaml(:\d+)?: /, "");
    m.className = "bad";
  }
}
async function refreshPreview() {
  if (S.previewBusy) { S.previewAgain = true; return; }
  S.previewBusy = true;
  try {
    do {
      S.previewAgain = false;
      const a = $("from").value, b = $("to").value, alpha = $("alpha").value;
      const r = await api(`/api/preview?from=${encodeURIComponent(a)}&to=${encodeURIComponent(b)}&alpha=${alpha}`);
      if (!r.ok) { $("preview-status").textContent = (await r.json()).error.message; break; }
      const version = +r.headers.get("X-Lipsync-Version");
      S.lastMethod = r.headers.get("X-Lipsync-Method");
      const blob = await r.blob();
      const img = $("preview");
      const old = img.src;
      await new Promise((done) => { img.onload = done; img.onerror = done; img.src = URL.createObjectURL(blob); });
      if (old.startsWith("blob:")) URL.revokeObjectURL(old);
      S.previewCount += 1;
      img.dataset.version = version;
      img.dataset.alpha = alpha;
      img.dataset.method = S.lastMethod;
      if (S.pendingSince !== null && version >= S.version) {
        S.lastUpdateMs = performance.now() - S.pendingSince;
        if (S.savedAt !== null && S.pendingSince === S.savedAt) S.saveToPreviewMs = S.lastUpdateMs;
        S.pendingSince = null;
      }
      showPreviewStatus();
    } while (S.previewAgain);
  } finally {
    S.previewBusy = false;
  }
}
function showPreviewStatus(status) {
  const s = status || S.lastStatus;
  let text = `method: ${S.lastMethod || "…"}`;
  if (S.lastMethod === "beier-neely") text += " (flows being computed)";
  if (S.lastUpdateMs !== null) text += ` · updated in ${Math.round(S.lastUpdateMs)} ms`;
  if (s) {
    const f = s.flows;
    text += f.total ? ` · flows ${f.done}/${f.total}` : " · flows ready";
    $("flow-bar").style.width = (f.total ? 100 * f.done / f.total : 100) + "%";
  }
  $("preview-status").textContent = text;
}
async function pollStatus() {
  try {
    const r = await api("/api/status");
    if (r.ok) {
      const s = await r.json();
      S.lastStatus = s;
      const a = $("from").value, b = $("to").value;
      const ready = s.version === S.version && s.ready.some((p) => (p[0] === a && p[1] === b) || (p[0] === b && p[1] === a));
      if (ready && S.lastMethod === "beier-neely" && !S.playing) refreshPreview();
      showPreviewStatus(s);
    }
  } finally {
    setTimeout(pollStatus, STATUS_EVERY_MS);
  }
}
async function play() {
  S.playing = !S.playing;
  $("play").textContent = S.playing ? "Stop" : "Play";
  let dir = 1;
  while (S.playing) {
    let a = +$("alpha").value + dir * PLAY_STEP;
    if (a >= 1) { a = 1; dir = -1; }
    if (a <= 0) { a = 0; dir = 1; }
    $("alpha").value = a;
    $("alpha-value").textContent = (+a).toFixed(2);
    await refreshPreview();
    // refreshPreview returns at once while another preview is in flight; without a real
    // pause this loop would spin on microtasks and starve the fetch it is waiting for.
    await new Promise((done) => setTimeout(done, PLAY_PAUSE_MS));
  }
}

// ---------------------------------------------------------------- start
async function start() {
  const r = await api("/api/bank");
  if (!r.ok) {
    document.body.textContent = "This page needs the URL lipsync edit printed (with its token).";
    return;
  }
  const info = await r.json();
  S.doc = info.doc;
  S.names = info.names;
  S.shape = info.shape;
  S.axis = info.doc.symmetry ? info.axis : null;
  S.version = info.version;
  $("path").textContent = info.path;
  showSymmetry();
  const [h, w] = S.shape;
  $("canvas-image").setAttribute("width", w);
  $("canvas-image").setAttribute("height", h);
  for (const id of ["from", "to", "copy-from"]) {
    const sel = $(id);
    for (const v of S.names) { const o = document.createElement("option"); o.value = o.textContent = v; sel.appendChild(o); }
  }
  const rest = S.doc.rest;
  $("from").value = rest;
  $("to").value = S.names.find((v) => v !== rest) || rest;
  buildThumbs();
  S.current = $("to").value;
  $("canvas-image").setAttribute("href", imageUrl(S.doc.visemes[S.current].image));
  fit();
  redraw();
  $("undo").onclick = undo;
  $("redo").onclick = redo;
  $("save").onclick = save;
  $("zoom-in").onclick = () => zoom(1 / 1.25);
  $("zoom-out").onclick = () => zoom(1.25);
  $("zoom-fit").onclick = fit;
  $("add").onclick = addLine;
  $("rename").onclick = renameLine;
  $("delete").onclick = deleteLine;
  $("copy").onclick = copyLines;
  $("face").onclick = placeFromFace;
  $("play").onclick = play;
  $("from").onchange = $("to").onchange = refreshPreview;
  $("alpha").addEventListener("input", () => { $("alpha-value").textContent = (+$("alpha").value).toFixed(2); refreshPreview(); });
  document.addEventListener("keydown", (e) => {
    if (e.target.tagName === "INPUT" && e.target.type === "text") return;
    if ((e.ctrlKey || e.metaKey) && e.key === "z") { e.preventDefault(); undo(); }
    if ((e.ctrlKey || e.metaKey) && (e.key === "y" || (e.shiftKey && e.key === "Z"))) { e.preventDefault(); redo(); }
    if ((e.ctrlKey || e.metaKey) && e.key === "s") { e.preventDefault(); save(); }
  });
  window.addEventListener("resize", drawCanvas);
  setupPanZoom();
  refreshPreview();
  pollStatus();
  document.body.dataset.ready = "1";
}
start();
