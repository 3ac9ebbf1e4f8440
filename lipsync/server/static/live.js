// The live demo: audio plays, its phones are pushed ahead of it, frames come back on its clock.
"use strict";

(function () {
  const token = new URLSearchParams(location.search).get("token") || "";
  const q = "token=" + encodeURIComponent(token);
  const canvas = document.getElementById("head");
  const ctx = canvas.getContext("2d");
  const audio = document.getElementById("audio");
  const play = document.getElementById("play");
  const status = document.getElementById("status");
  const show = (id, v) => { document.getElementById(id).textContent = String(v); };

  // Events are pushed this far ahead of the audio, as a TTS engine sends them before the
  // sound: more than the server's look-ahead (380 ms), so every frame arrives final.
  const PUSH_AHEAD_S = 1.0;
  // How often the clock is sent; the server extrapolates between messages.
  const CLOCK_EVERY_MS = 100;

  const stats = { frames: 0, final: 0, errors: 0, lastN: -1, provisional: [] };
  window.lipsyncDemo = stats;  // read by the browser test
  let events = [], pushed = 0, ws = null, timer = null;
  let clockStart = null;       // fallback clock when the audio cannot play (no sound device)

  function now() {
    if (clockStart !== null) return (performance.now() - clockStart) / 1000;
    return audio.currentTime;
  }

  function send(obj) { if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(obj)); }

  function tick() {
    const t = now();
    const due = [];
    while (pushed < events.length && events[pushed].start <= t + PUSH_AHEAD_S) due.push(events[pushed++]);
    if (due.length) send({ type: "push", events: due });
    send({ type: "clock", t: t });
    show("clock", t.toFixed(2) + " s");
    const end = events.length ? events[events.length - 1].end : 0;
    if ((clockStart !== null && t > end + 0.5) || (clockStart === null && audio.ended)) {
      send({ type: "stop" });
      clearInterval(timer); timer = null;
      play.disabled = false;
      status.textContent = "done: " + stats.frames + " frames";
    }
  }

  async function draw(buf) {
    const view = new DataView(buf);
    const n = view.getUint32(0, true), flags = view.getUint32(4, true), t = view.getFloat64(8, true);
    const bitmap = await createImageBitmap(new Blob([buf.slice(16)], { type: "image/jpeg" }));
    ctx.drawImage(bitmap, 0, 0, canvas.width, canvas.height);
    bitmap.close();
    stats.frames++; stats.lastN = n;
    if (flags & 1) stats.final++; else stats.provisional.push(n);
    show("frames", stats.frames); show("final", stats.final);
    show("lag", ((now() - t) * 1000).toFixed(0) + " ms");
  }

  function connect() {
    const scheme = location.protocol === "https:" ? "wss://" : "ws://";
    ws = new WebSocket(scheme + location.host + "/ws/live?" + q);
    ws.binaryType = "arraybuffer";
    ws.onmessage = (e) => {
      if (typeof e.data !== "string") { draw(e.data); return; }
      const msg = JSON.parse(e.data);
      if (msg.type === "ready") {
        canvas.width = msg.width; canvas.height = msg.height;
        status.textContent = "ready: " + msg.width + "×" + msg.height + " at " + msg.fps + " fps";
        play.disabled = events.length === 0;
        send({ type: "clock", t: 0 }); send({ type: "stop" });  // draw the resting face once
      } else if (msg.type === "error") {
        stats.errors++; show("errors", stats.errors);
        status.textContent = "server: " + msg.error;
      }
    };
    ws.onclose = () => { status.textContent = "disconnected"; play.disabled = true; };
  }

  async function start() {
    play.disabled = true;
    pushed = 0;
    clockStart = null;
    audio.currentTime = 0;
    try {
      await audio.play();
    } catch (err) {
      clockStart = performance.now();  // no sound output: keep time ourselves
      status.textContent = "audio cannot play here (" + err.name + "); using a silent clock";
    }
    if (timer) clearInterval(timer);
    timer = setInterval(tick, CLOCK_EVERY_MS);
    tick();
  }

  play.addEventListener("click", start);
  fetch("/api/demo?" + q).then((r) => r.json()).then((demo) => {
    if (demo.error) { status.textContent = demo.error; return; }
    events = demo.events;
    audio.src = demo.audio + "?" + q;
    connect();
  }).catch((err) => { status.textContent = "cannot load the demo: " + err; });
})();
