// lipsync atlas player: what an engine does with an atlas, its frames.json and the speech.
//
// Every animation frame: t = the audio clock (audio.currentTime), n = floor(t * fps) (the
// last frame after the end), cell = frames[n]; draw the base image, then the cell's
// rectangle of the texture into the atlas' region. The documents are described in
// lipsync/atlas/schema.py; this file reads version 1.
"use strict";

(function () {
  const ATLAS_FORMAT = "lipsync-atlas";
  const FRAMES_FORMAT = "lipsync-atlas-frames";
  const VERSION = 1;
  const LOG_LENGTH = 2000;  // recent draws kept for inspection (tests read them)

  const canvas = document.getElementById("view");
  const ctx = canvas.getContext("2d");
  const audio = document.getElementById("audio");
  const playButton = document.getElementById("play");
  const status = document.getElementById("status");

  // The state, readable from outside (the browser test and the console).
  const player = {
    ready: false, errors: 0, draws: 0, lastFrame: -1, lastCell: -1, lastTime: NaN,
    log: [], atlas: null, frames: null, drawAt: drawAt, frameAt: frameAt,
  };
  window.lipsyncAtlasPlayer = player;

  let texture = null, base = null, wallStart = null, wallOffset = 0;

  function say(text, isError) {
    status.textContent = text;
    status.className = isError ? "error" : "";
    if (isError) player.errors += 1;
  }

  function fail(message) { throw new Error(message); }

  function wholeNumbers(value, n) {
    return Array.isArray(value) && value.length === n && value.every((x) => Number.isInteger(x) && x >= 0);
  }

  function checkAtlas(doc) {
    if (!doc || doc.format !== ATLAS_FORMAT) fail("not a lipsync atlas (format " + ATLAS_FORMAT + ")");
    if (!Number.isInteger(doc.version) || doc.version > VERSION) fail("atlas version " + doc.version + " is newer than this player");
    if (!wholeNumbers(doc.frame_size, 2) || !wholeNumbers(doc.region, 4) || !wholeNumbers(doc.image_size, 2)) {
      fail("atlas sizes are not whole numbers");
    }
    if (!Array.isArray(doc.cells) || doc.cells.length === 0) fail("the atlas has no cells");
    doc.cells.forEach((c, i) => {
      if (!c || !wholeNumbers(c.rect, 4)) fail("cell " + i + " has no rectangle");
    });
    return doc;
  }

  function checkFrames(doc, atlas) {
    if (!doc || doc.format !== FRAMES_FORMAT) fail("not lipsync atlas frames (format " + FRAMES_FORMAT + ")");
    if (!Number.isInteger(doc.version) || doc.version > VERSION) fail("frames version " + doc.version + " is newer than this player");
    if (!(doc.fps > 0) || !Array.isArray(doc.frames) || doc.frames.length === 0) {
      fail("frames.json needs fps and at least one frame");
    }
    const bad = doc.frames.findIndex((c) => !Number.isInteger(c) || c < 0 || c >= atlas.cells.length);
    if (bad >= 0) fail("frame " + bad + " names cell " + doc.frames[bad] + ", which the atlas does not have");
    return doc;
  }

  // The frame shown at time t: frame n covers [n / fps, (n + 1) / fps).
  function frameAt(t) {
    const frames = player.frames.frames;
    const n = Math.floor(t * player.frames.fps + 1e-9);
    return Math.min(Math.max(n, 0), frames.length - 1);
  }

  function drawAt(t) {
    if (!player.ready) return null;
    const atlas = player.atlas;
    const n = frameAt(t);
    const cell = player.frames.frames[n];
    const [fw, fh] = atlas.frame_size;
    const [rx, ry, rw, rh] = atlas.region;
    const [x, y, w, h] = atlas.cells[cell].rect;
    // at scale 1 every pixel is copied as it is; scaled atlases are drawn back up smoothly
    ctx.imageSmoothingEnabled = atlas.scale !== 1;
    ctx.clearRect(0, 0, fw, fh);
    if (base) ctx.drawImage(base, 0, 0, fw, fh);
    ctx.drawImage(texture, x, y, w, h, rx, ry, rw, rh);
    player.draws += 1;
    player.lastFrame = n;
    player.lastCell = cell;
    player.lastTime = t;
    player.log.push([t, n, cell]);
    if (player.log.length > LOG_LENGTH) player.log.splice(0, player.log.length - LOG_LENGTH);
    return { frame: n, cell: cell };
  }

  // The clock: the audio's when there is a sound, else the wall clock (a silent preview).
  function now() {
    if (audio.src) return audio.currentTime;
    if (wallStart === null) return wallOffset;
    return wallOffset + (performance.now() - wallStart) / 1000;
  }

  function playing() {
    return audio.src ? !audio.paused : wallStart !== null;
  }

  let lastDrawn = NaN;
  function tick() {
    const t = now();
    if (player.ready && (playing() || t !== lastDrawn)) {
      drawAt(t);
      lastDrawn = t;
    }
    if (!audio.src && wallStart !== null && now() > player.frames.duration) stop();
    requestAnimationFrame(tick);
  }

  function stop() {
    if (audio.src) audio.pause();
    else if (wallStart !== null) { wallOffset = now(); wallStart = null; }
    playButton.textContent = "Play";
  }

  playButton.addEventListener("click", () => {
    if (playing()) { stop(); return; }
    if (audio.src) {
      if (audio.ended) audio.currentTime = 0;
      audio.play().catch((e) => say("cannot play the sound: " + e.message, true));
    } else {
      if (wallOffset >= player.frames.duration) wallOffset = 0;
      wallStart = performance.now();
    }
    playButton.textContent = "Pause";
  });
  audio.addEventListener("ended", () => { playButton.textContent = "Play"; });

  function loadImage(url) {
    return new Promise((resolve, reject) => {
      const img = new Image();
      img.onload = () => resolve(img);
      img.onerror = () => reject(new Error("cannot load the image " + url));
      img.src = url;
    });
  }

  async function fetchJson(url) {
    const response = await fetch(url);
    if (!response.ok) fail("cannot load " + url + " (" + response.status + ")");
    return response.json();
  }

  // urlOf(name) gives the URL of a file the atlas names (beside it, or a picked file).
  async function start(atlasDoc, framesDoc, urlOf, audioUrl) {
    const atlas = checkAtlas(atlasDoc);
    const frames = checkFrames(framesDoc, atlas);
    texture = await loadImage(urlOf(atlas.image));
    base = atlas.base ? await loadImage(urlOf(atlas.base)) : null;
    if (texture.naturalWidth !== atlas.image_size[0] || texture.naturalHeight !== atlas.image_size[1]) {
      fail("the texture is " + texture.naturalWidth + " x " + texture.naturalHeight + ", the atlas says " +
           atlas.image_size.join(" x "));
    }
    player.atlas = atlas;
    player.frames = frames;
    canvas.width = atlas.frame_size[0];
    canvas.height = atlas.frame_size[1];
    if (audioUrl) audio.src = audioUrl; else audio.removeAttribute("src");
    player.ready = true;
    lastDrawn = NaN;
    playButton.disabled = false;
    say("ready: " + frames.count + " frames at " + frames.fps + " fps, " + atlas.cells.length + " cells" +
        (frames.missing_pairs && frames.missing_pairs.length ? " (" + frames.missing_pairs.length +
         " transitions not in the atlas)" : "") + (audioUrl ? "" : "; no sound: the wall clock plays"));
  }

  async function fromQuery() {
    const q = new URLSearchParams(location.search);
    if (!q.get("atlas") || !q.get("frames")) return;
    say("loading");
    const atlasUrl = new URL(q.get("atlas"), location.href);
    const atlasDoc = await fetchJson(atlasUrl);
    const framesDoc = await fetchJson(new URL(q.get("frames"), location.href));
    const audioUrl = q.get("audio") ? new URL(q.get("audio"), location.href).href : null;
    await start(atlasDoc, framesDoc, (name) => new URL(name, atlasUrl).href, audioUrl);
  }

  async function fromFiles(files) {
    const byName = new Map();
    let atlasDoc = null, framesDoc = null, audioFile = null;
    for (const file of files) {
      byName.set(file.name, file);
      if (file.name.toLowerCase().endsWith(".json")) {
        const doc = JSON.parse(await file.text());
        if (doc && doc.format === ATLAS_FORMAT) atlasDoc = doc;
        else if (doc && doc.format === FRAMES_FORMAT) framesDoc = doc;
      } else if (file.type.startsWith("audio/")) {
        audioFile = file;
      }
    }
    if (!atlasDoc) fail("pick the atlas JSON (written by lipsync atlas)");
    if (!framesDoc) fail("pick frames.json (written by lipsync cues --format atlas)");
    const urlOf = (name) => {
      const file = byName.get(name);
      if (!file) fail("pick " + name + " too (the atlas names it)");
      return URL.createObjectURL(file);
    };
    await start(atlasDoc, framesDoc, urlOf, audioFile ? URL.createObjectURL(audioFile) : null);
  }

  document.getElementById("files").addEventListener("change", (event) => {
    stop();
    player.ready = false;
    fromFiles(Array.from(event.target.files)).catch((e) => say(e.message, true));
  });
  document.addEventListener("keydown", (event) => {
    if (event.key === " " && !playButton.disabled && event.target.tagName !== "INPUT") {
      event.preventDefault();
      playButton.click();
    }
  });

  fromQuery().catch((e) => say(e.message, true));
  requestAnimationFrame(tick);
})();
