"""Render jobs: an uploaded timeline (or audio, with optional text) to an mp4, one at a time.

Each job gets its own folder inside the server's temporary folder; the upload is written
there under a fixed name with the client's extension only (which picks the reader), the
transcript (if any) beside it as a file -- a client's text is never taken as a path --,
and :func:`lipsync.clip.render_clip` writes ``out.mp4`` there, atomically. Finished jobs
are kept until :data:`MAX_KEPT` newer ones exist, then their folder is removed.
"""

from __future__ import annotations

import re
import secrets
import shutil
import threading
import types
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
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

    def __init__(self, root: Path, *, bank, store, fps: float, map, timing, method: str):
        self.root = root
        self.bank, self.store, self.fps, self.map, self.timing, self.method = bank, store, fps, map, timing, method
        self._jobs: "OrderedDict[str, Job]" = OrderedDict()
        self._lock = threading.Lock()
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="lipsync-render")

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
            from ..sequencer import check_fps

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
        self._executor.submit(self._run, job, source, options, self.fps if fps is None else fps)
        return job

    def _run(self, job: Job, source: Path, options, fps: float) -> None:
        from ..clip import render_clip

        job.state = "running"

        def progress(done: int, total: int) -> None:
            job.progress, job.frames = done / max(total, 1), done

        try:
            render_clip(str(source), str(job.folder / "out.mp4"), bank=self.bank, store=self.store, fps=fps,
                        map=self.map, timing=self.timing, method=self.method, quiet=True,
                        timeline_options=options, progress=progress)
            job.state, job.progress = "done", 1.0
        except InputError as exc:
            # the server's paths mean nothing to the client: name its upload instead
            job.error = str(exc).replace(str(source), job.name).replace(str(job.folder), "")
            job.state = "error"
        except Exception as exc:  # reported to the client; the server carries on
            job.error = f"render failed: {type(exc).__name__}: {str(exc)[:200]}".replace(str(job.folder), "")
            job.state = "error"

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
        self._executor.shutdown(wait=True, cancel_futures=True)


class Busy(RuntimeError):
    """Too many jobs pending (HTTP 503)."""
