// AudioWorklet: the microphone's samples as 16-bit PCM blocks of 20 ms, posted to the page.
"use strict";

class PcmCapture extends AudioWorkletProcessor {
  constructor() {
    super();
    // 20 ms at the context's rate: what the server processes at a time (one block)
    this.size = Math.round(sampleRate * 0.02);
    this.buf = new Int16Array(this.size);
    this.fill = 0;
  }

  process(inputs) {
    const input = inputs[0];
    if (!input || input.length === 0) return true;
    const ch = input[0];  // mono: the first channel (the page asks for one)
    for (let i = 0; i < ch.length; i++) {
      const x = Math.max(-1, Math.min(1, ch[i]));
      // the server reads floats as round(x * 32768), clipped: the same here
      this.buf[this.fill++] = Math.max(-32768, Math.min(32767, Math.round(x * 32768)));
      if (this.fill === this.size) {
        this.port.postMessage(this.buf.buffer, [this.buf.buffer]);
        this.buf = new Int16Array(this.size);
        this.fill = 0;
      }
    }
    return true;
  }
}

registerProcessor("pcm-capture", PcmCapture);
