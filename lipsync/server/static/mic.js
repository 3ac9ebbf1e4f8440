// The microphone page: capture (getUserMedia + AudioWorklet), stream 16-bit PCM, show the
// frames the server returns when the delayed audio reaches them.
"use strict";

(function () {
  const params = new URLSearchParams(location.search);
  const q = "token=" + encodeURIComponent(params.get("token") || "");
  const canvas = document.getElementById("head");
  const ctx2d = canvas.getContext("2d");
  const startBtn = document.getElementById("start");
  const stopBtn = document.getElementById("stop");
  const monitor = document.getElementById("monitor");
  const status = document.getElementById("status");
  const show = (id, v) => { document.getElementById(id).textContent = String(v); };

  // What the page did, for the browser test and for anyone curious (console: lipsyncMic).
  const stats = { frames: 0, drawn: 0, errors: 0, samples: 0, rate: 0, lookahead: null, fps: 25,
                  specs: {}, numbers: [], maxLateMs: 0, started: false, stoppedAt: null, endFrames: null };
  window.lipsyncMic = stats;
  let ws = null, audioCtx = null, stream = null, node = null, delay = null, source = null;
  const pending = [];   // decoded frames waiting for their time: [n, bitmap]

  function send(data) { if (ws && ws.readyState === WebSocket.OPEN) ws.send(data); }

  // Audio time the head shows now: the audio sent, less the look-ahead (the frame of time t
  // is made when the audio reaches t + look-ahead).
  // After Stop no audio comes: the head plays on in real time to the end of what was sent
  // (the last look-ahead's frames, which the server sends on {"type": "end"}).
  function headTime() {
    if (!stats.rate) return 0;
    const sent = stats.samples / stats.rate;
    if (stats.stoppedAt === null) return sent - stats.lookahead;
    return Math.min(sent, sent - stats.lookahead + (performance.now() / 1000 - stats.stoppedAt));
  }

  function drawDue() {
    const t = headTime();
    let best = null;
    while (pending.length && pending[0][0] / stats.fps <= t + 1e-6) {
      if (best) best[1].close();
      best = pending.shift();
    }
    if (best) {
      ctx2d.drawImage(best[1], 0, 0, canvas.width, canvas.height);
      best[1].close();
      stats.drawn++;
    }
    const ending = stats.stoppedAt !== null && (stats.endFrames === null || pending.length);
    if (stats.started || ending) requestAnimationFrame(drawDue);
  }

  async function onFrame(buf) {
    const view = new DataView(buf);
    const n = view.getUint32(0, true);
    stats.frames++; stats.numbers.push(n);
    const late = (headTime() - n / stats.fps) * 1000;   // > 0: it came after its time
    stats.maxLateMs = Math.max(stats.maxLateMs, late);
    show("frames", stats.frames); show("late", late.toFixed(0) + " ms");
    const bitmap = await createImageBitmap(new Blob([buf.slice(16)], { type: "image/jpeg" }));
    pending.push([n, bitmap]);
    pending.sort((a, b) => a[0] - b[0]);
    if (!stats.started) { ctx2d.drawImage(bitmap, 0, 0, canvas.width, canvas.height); }
  }

  function connect() {
    const scheme = location.protocol === "https:" ? "wss://" : "ws://";
    ws = new WebSocket(scheme + location.host + "/ws/live?" + q);
    ws.binaryType = "arraybuffer";
    ws.onmessage = (e) => {
      if (typeof e.data !== "string") { onFrame(e.data); return; }
      const msg = JSON.parse(e.data);
      if (msg.type === "ready") {
        canvas.width = msg.width; canvas.height = msg.height;
        stats.fps = msg.fps; stats.lookahead = msg.audio_lookahead;
        show("lookahead", Math.round(stats.lookahead * 1000) + " ms");
        status.textContent = "ready: press Start and speak";
        startBtn.disabled = false;
      } else if (msg.type === "config") {
        if (msg.audio_lookahead !== undefined) {
          stats.lookahead = msg.audio_lookahead;
          show("lookahead", Math.round(stats.lookahead * 1000) + " ms");
        }
      } else if (msg.type === "end") {
        stats.endFrames = msg.frames;
        status.textContent += "; " + msg.frames + " frames in all";
      } else if (msg.type === "spec") {
        stats.specs[msg.n] = [msg.from, msg.to, msg.alpha];
      } else if (msg.type === "error") {
        stats.errors++; show("errors", stats.errors);
        status.textContent = "server: " + msg.error;
      }
    };
    ws.onclose = () => { status.textContent = "disconnected"; startBtn.disabled = true; };
  }

  async function start() {
    startBtn.disabled = true;
    try {
      // context, worklet and session first: the server loads its recogniser (~0.5 s) and
      // the worklet is running before the first sample is captured, so none is lost or late
      audioCtx = new AudioContext();
      await audioCtx.audioWorklet.addModule("/static/mic-worklet.js");
      stats.rate = audioCtx.sampleRate;
      const config = { type: "config", audio_rate: stats.rate, specs: true };
      if (params.has("lookahead")) config.lookahead = Number(params.get("lookahead"));
      send(JSON.stringify(config));
      stream = await navigator.mediaDevices.getUserMedia({ audio: {
        channelCount: 1, echoCancellation: false, noiseSuppression: false, autoGainControl: false } });
    } catch (err) {
      status.textContent = "no microphone: " + err.name + " " + err.message;
      startBtn.disabled = false;
      return;
    }
    source = audioCtx.createMediaStreamSource(stream);
    node = new AudioWorkletNode(audioCtx, "pcm-capture");
    node.port.onmessage = (e) => {
      send(e.data);
      stats.samples += e.data.byteLength / 2;
      show("sent", (stats.samples / stats.rate).toFixed(2) + " s");
    };
    // the worklet runs only when its output is pulled: through a silent gain to the speakers
    const mute = audioCtx.createGain();
    mute.gain.value = 0;
    source.connect(node).connect(mute).connect(audioCtx.destination);
    // "hear myself": the voice delayed by the look-ahead, in step with the mouth
    delay = audioCtx.createDelay(2.0);
    delay.delayTime.value = stats.lookahead || 0;
    const level = audioCtx.createGain();
    level.gain.value = monitor.checked ? 1 : 0;
    monitor.onchange = () => { level.gain.value = monitor.checked ? 1 : 0; };
    source.connect(delay).connect(level).connect(audioCtx.destination);
    stats.started = true;
    stopBtn.disabled = false;
    status.textContent = "listening at " + stats.rate + " Hz";
    requestAnimationFrame(drawDue);
  }

  function stop() {
    stats.started = false;
    stats.stoppedAt = performance.now() / 1000;
    if (node) { node.port.onmessage = null; node.disconnect(); }   // nothing is sent after the end
    // the stream has ended: the server sends the frames of its last look-ahead, drawn as
    // the head's time reaches them
    if (stats.samples) { send(JSON.stringify({ type: "end" })); requestAnimationFrame(drawDue); }
    if (stream) stream.getTracks().forEach((t) => t.stop());
    if (audioCtx) audioCtx.close();
    stopBtn.disabled = true;
    status.textContent = "stopped: " + (stats.samples / (stats.rate || 1)).toFixed(2) + " s sent, " +
      stats.frames + " frames";
  }

  startBtn.addEventListener("click", start);
  stopBtn.addEventListener("click", stop);
  connect();
})();
