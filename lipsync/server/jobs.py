"""Render jobs: an uploaded timeline (or audio, with optional text) to an mp4, one at a time.

Each job gets its own folder inside the server's temporary folder; the upload is written
there under a fixed name with the client's extension only (which picks the reader), the
transcript (if any) beside it as a file -- a client's text is never taken as a path --,
and :func:`lipsync.pipeline.clip.render_clip` writes ``out.mp4`` there, atomically. Finished jobs
are kept until :data:`MAX_KEPT` newer ones exist, then their folder is removed.

Bounds (issue 32): a job longer than ``max_clip_seconds`` of video (a 16-byte timeline can
say ten hours) fails before any frame, and one running longer than ``job_timeout`` seconds
is stopped, so a queued job starts within ``(MAX_PENDING - 1) * job_timeout`` seconds
whatever came before it. :meth:`Jobs.close` (SIGTERM, Ctrl-C) cancels the running job and
returns within :data:`STOP_WAIT_S`.

Each job runs in a forked worker process of its own (issue 38), so the timeout and a
shutdown stop it in any stage -- reading, aligning, planning or rendering -- by killing
its process group (the worker and its ffmpeg); the queue's thread relays its progress.
"""

from __future__ import annotations

import multiprocessing
import os
import queue
import re
import secrets
import shutil
import signal
import threading
import time
import types
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from ..errors import InputError

#: Jobs waiting or running at once; more are refused with 503 (rendering is CPU-bound, a
#: queue longer than a few clips only delays everyone).
MAX_PENDING = 4
#: Finished jobs whose files are kept for download.
MAX_KEPT = 16
#: Longest transcript accepted with an audio upload (a few minutes of speech).
MAX_TEXT_CHARS = 20_000

#: Longest clip a job renders, seconds of video (``--max-clip-seconds``): ten minutes, far
#: beyond a talking-head clip, and rendered in a few minutes even on two cores.
DEFAULT_MAX_CLIP_S = 600.0
#: Wall-clock seconds a job may run before it is stopped (``--job-timeout``): a ten-minute
#: clip renders in about a minute on two cores (`lipsync render`: 5-12x real time).
DEFAULT_JOB_TIMEOUT_S = 300.0
#: How long :meth:`Jobs.close` waits for the cancelled job to unwind (ffmpeg killed, partial
#: output removed) before the server goes on shutting down.
STOP_WAIT_S = 1.0

_EXTENSION = re.compile(r"^\.[A-Za-z0-9]{1,10}$")


@dataclass
class Job:
    id: str
    folder: Path
    name: str
    state: str = "queued"      # queued, running, done, error
    progress: float = 0.0
    error: Optional[str] = None
    frames: int = 0

    def as_json(self) -> dict:
        return {"job": self.id, "state": self.state, "progress": round(self.progress, 3), "error": self.error,
                "frames": self.frames, "video": f"/api/jobs/{self.id}/video" if self.state == "done" else None}


class Jobs:
    """The render queue of one server (module docstring)."""

    def __init__(self, root: Path, *, bank, store, fps: float, map, timing, method: str,
                 max_clip_seconds: float = DEFAULT_MAX_CLIP_S, job_timeout: float = DEFAULT_JOB_TIMEOUT_S,
                 samples=None):
        self.root = root
        self.samples = samples   # --samples on|off (None: bank.yaml's), as the live sessions
        self.bank, self.store, self.fps, self.map, self.timing, self.method = bank, store, fps, map, timing, method
        self.max_clip_seconds, self.job_timeout = float(max_clip_seconds), float(job_timeout)
        self._jobs: "OrderedDict[str, Job]" = OrderedDict()
        self._lock = threading.Lock()
        self._queue: "queue.Queue" = queue.Queue()
        self._stop = threading.Event()
        self._worker = threading.Thread(target=self._serve_queue, name="lipsync-render", daemon=True)
        self._worker.start()

    def submit(self, data: bytes, name: str, *, text: Optional[str] = None, timeline_format: Optional[str] = None,
               fps: Optional[float] = None, lang: Optional[str] = None) -> Job:
        """Queue ``data`` (a timeline or audio file called ``name`` by the client)."""
        from ..readers import READERS

        ext = Path(name or "").suffix
        if ext and not _EXTENSION.match(ext):
            raise InputError(f"upload name {name[:60]!r}: unusable extension")
        if timeline_format is not None:
            READERS.get(timeline_format)  # UnknownNameError lists the valid ones
        if lang is not None:
            from ..phonetics.g2p import is_english, resolve

            if not is_english(lang):
                resolve(lang)  # UnknownLanguageError lists the codes
        if fps is not None:
            from ..motion.sequencer import check_fps

            fps = check_fps(fps)
        if text is not None and len(text) > MAX_TEXT_CHARS:
            raise InputError(f"text is over {MAX_TEXT_CHARS} characters")
        if not data:
            raise InputError("empty upload: send the timeline or audio file as the request body")
        with self._lock:
            pending = sum(j.state in ("queued", "running") for j in self._jobs.values())
            if pending >= MAX_PENDING:
                raise Busy(f"{pending} render jobs are already waiting; try again later")
            job_id = secrets.token_hex(8)
            folder = self.root / job_id
            folder.mkdir()
            job = Job(job_id, folder, Path(name or "upload").name[:80])
            self._jobs[job_id] = job
            self._forget_old()
        source = folder / f"input{ext}"
        source.write_bytes(data)
        options = types.SimpleNamespace(timeline_format=timeline_format, tier=None, sample_rate=16000,
                                        moho_fps=24.0, text=None, lang=lang)
        if text:
            transcript = folder / "transcript.txt"
            transcript.write_text(text, encoding="utf-8")
            options.text = str(transcript)
        self._queue.put((job, source, options, self.fps if fps is None else fps))
        return job

    def _serve_queue(self) -> None:
        while not self._stop.is_set():
            item = self._queue.get()
            if item is None or self._stop.is_set():
                break
            self._run(*item)

    def _clip(self, source: Path, options):
        """What to render, after checking its length: a Timeline read here, or the audio path
        (its decoded length checked before the long alignment)."""
        from ..readers import read_timeline
        from ..readers.audio import is_audio_input

        if is_audio_input(source, options.timeline_format):
            from ..speech.audio import SAMPLE_RATE, load_audio

            # decoded (a header's duration can lie), and no further than just past the limit
            seconds = len(load_audio(source, max_seconds=self.max_clip_seconds + 1)) / SAMPLE_RATE
            clip, length = str(source), f"more than {self.max_clip_seconds:g} s"
        else:
            clip = read_timeline(source, options.timeline_format, tier=options.tier, sample_rate=options.sample_rate,
                                 fps=options.moho_fps)
            seconds = clip.end
            length = f"{seconds:.0f} s"
        if seconds > self.max_clip_seconds:
            raise InputError(f"lasts {length}; this server renders at most {self.max_clip_seconds:g} s per job "
                             f"(--max-clip-seconds)", path=source)
        return clip

    def _run(self, job: Job, source: Path, options, fps: float) -> None:
        job.state = "running"
        deadline = time.monotonic() + self.job_timeout
        receive, send = _FORK.Pipe(duplex=False)
        worker = _FORK.Process(target=self._render_in_worker, args=(send, source, options, fps, job.folder, os.getpid()),
                               name=f"lipsync-job-{job.id}", daemon=True)
        worker.start()
        send.close()
        outcome = None
        try:
            outcome = self._follow(job, worker, receive, deadline)
        finally:
            if worker.is_alive():   # over its time, or the server stopping: the whole job goes
                _kill_group(worker)
            worker.join()
            receive.close()
        if outcome is None:
            outcome = ("error", "render failed: the job's worker ended without a result")
        kind, message = outcome
        if kind == "done":
            job.state, job.progress = "done", 1.0
            return
        _remove_partials(job.folder)
        if kind == "input":
            # the server's paths mean nothing to the client: name its upload instead
            message = message.replace(str(source), job.name)
        job.error, job.state = message.replace(str(job.folder), ""), "error"

    def _follow(self, job: Job, worker, receive, deadline: float):
        """Relay the worker's progress into ``job`` until it reports its outcome, or stop it."""
        while True:
            if self._stop.is_set():
                return ("stopped", "the server is shutting down")
            left = deadline - time.monotonic()
            if left <= 0:
                return ("stopped", f"stopped after {self.job_timeout:g} s (--job-timeout)")
            try:
                ready = receive.poll(min(left, _POLL_S))
                message = receive.recv() if ready else None
            except (EOFError, OSError):
                return None   # the worker died without a word (killed from outside, out of memory)
            if message is None:
                continue
            if message[0] == "progress":
                _, done, total = message
                job.progress, job.frames = done / max(total, 1), done
            else:
                return message

    def _render_in_worker(self, send, source: Path, options, fps: float, folder: Path, parent: int) -> None:
        """The job itself, in a forked worker process that can be killed at any stage
        (reading, aligning, planning, rendering): its own process group, so its ffmpeg goes
        with it."""
        from .._proc import die_with_parent
        from ..encode import ffmpeg
        from ..pipeline.clip import render_clip

        # its own group takes it out of the server's, so a server killed with SIGKILL would
        # leave it rendering on: the kernel ends it with the server instead
        die_with_parent(parent)
        os.setpgrp()
        ffmpeg.OWN_SESSION = False   # its ffmpeg stays in this group, and is killed with it
        try:
            render_clip(self._clip(source, options), str(folder / "out.mp4"), bank=self.bank, store=self.store,
                        fps=fps, map=self.map, timing=self.timing, method=self.method, quiet=True,
                        samples=self.samples, timeline_options=options, progress=lambda done, total: send.send(("progress", done, total)))
            send.send(("done", ""))
        except InputError as exc:
            send.send(("input", str(exc)))
        except Exception as exc:  # reported to the client; the server carries on
            send.send(("error", f"render failed: {type(exc).__name__}: {str(exc)[:200]}"))
        finally:
            send.close()

    def get(self, job_id: str) -> Optional[Job]:
        with self._lock:
            return self._jobs.get(job_id)

    def video(self, job: Job) -> Optional[Path]:
        path = job.folder / "out.mp4"
        return path if job.state == "done" and path.is_file() else None

    def _forget_old(self) -> None:
        finished = [j for j in self._jobs.values() if j.state in ("done", "error")]
        for job in finished[:max(0, len(finished) - MAX_KEPT)]:
            del self._jobs[job.id]
            shutil.rmtree(job.folder, ignore_errors=True)

    def close(self) -> None:
        """Cancel the running job and drop the queued ones; returns within :data:`STOP_WAIT_S`."""
        self._stop.set()
        self._queue.put(None)
        self._worker.join(STOP_WAIT_S)


#: How often the server looks at a running job (its progress, its deadline, a shutdown).
_POLL_S = 0.05
#: Jobs run in a forked worker: it shares the loaded bank and flow store without copying or
#: pickling them, and can be killed wherever it is (issue 38: a quadratic planning step ran
#: 207 s past a 15 s --job-timeout, as only the render loop looked at the deadline).
_FORK = multiprocessing.get_context("fork")


def _kill_group(worker) -> None:
    """SIGKILL the worker and everything it started (ffmpeg), which share its process group."""
    try:
        os.killpg(worker.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        worker.kill()


def _remove_partials(folder: Path) -> None:
    """A stopped or failed job's partial output (the upload and transcript stay until the job is forgotten)."""
    for path in folder.glob("*out*"):
        try:
            shutil.rmtree(path) if path.is_dir() and not path.is_symlink() else path.unlink()
        except OSError:
            pass


class Busy(RuntimeError):
    """Too many jobs pending (HTTP 503)."""


class Stopped(RuntimeError):
    """A job cancelled: over its time, or the server stopping."""
