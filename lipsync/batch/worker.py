"""Stage 3 of a batch, on the workers: one task per bank pair flow, one task per clip.

Workers share no files with the client: a task gets bytes (the bank pack, the clip's input
files) and returns bytes (the rendered video). So any dask.distributed cluster whose
workers have the package installed can run a batch.

* :func:`pair_task` computes one pair's flows into this machine's store (or finds them
  there from an earlier batch) and returns the store entry's bytes. Each pair runs once per
  cluster; dask copies the results to the workers whose clips need them.
* :func:`clip_task` installs the shipped entries this machine lacks, writes the inputs
  into a temporary folder and calls :func:`lipsync.pipeline.clip.render_clip` (the same pipeline as
  ``lipsync render``), then returns the mp4's bytes. Errors are returned, not raised, so a
  bad clip is a report row and dask does not retry it.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple

from .bankpack import BankPack, default_cache_dir, install_entries, local_bank


@dataclass(frozen=True)
class TimelineOptions:
    """Reader options passed to :func:`lipsync.pipeline.clip.render_clip` (``timeline_options``).

    ``text`` is the transcript for audio input (the audio reader reads it); the others are
    the readers' defaults, which a manifest does not change.
    """

    text: Optional[str] = None
    timeline_format: Optional[str] = None
    tier: Optional[str] = None
    sample_rate: float = 16000
    moho_fps: float = 24.0


@dataclass(frozen=True)
class ClipTask:
    """What a worker needs to render one clip: options and the input files' bytes.

    ``files`` maps a role (``input``, ``audio``, ``text``, ``map``) to ``(file name,
    bytes, the client's path)``; the client's path is only used to name the file in errors.
    """

    line: int
    output: str
    files: Dict[str, Tuple[str, bytes, str]]
    text: Optional[str]
    fps: float
    map: str
    timing: str
    method: str


_WORK_PREFIX = "clip-"
_cleaned: set = set()


def _work_folder(cache_dir: Path) -> Path:
    """A fresh temporary folder for one clip, under ``cache/tmp``.

    Named after this process, so that the first clip of each process can remove what
    killed workers left behind (folders whose process no longer exists).
    """
    tmp = cache_dir / "tmp"
    tmp.mkdir(parents=True, exist_ok=True)
    if str(tmp) not in _cleaned:
        _cleaned.add(str(tmp))
        for p in tmp.glob(f"{_WORK_PREFIX}*"):
            try:
                os.kill(int(p.name[len(_WORK_PREFIX):].split("-")[0]), 0)
            except (ValueError, ProcessLookupError):
                shutil.rmtree(p, ignore_errors=True)
            except PermissionError:  # another user's live process
                pass
    return Path(tempfile.mkdtemp(prefix=f"{_WORK_PREFIX}{os.getpid()}-", dir=tmp))


def pair_task(pack: BankPack, a: str, b: str, cache: Optional[str] = None) -> Tuple[str, bytes]:
    """Flows of the pair (a, b) of ``pack``'s bank, a before b in bank order: ``(store key, entry bytes)``.

    Computed into this machine's store under ``cache`` unless an earlier batch left the
    entry there.

    Examples
    --------
    >>> import tempfile
    >>> from lipsync._data import default_bank_dir
    >>> from lipsync.batch import pack_bank
    >>> pack = pack_bank(default_bank_dir())
    >>> key, data = pair_task(pack, pack.names[0], pack.names[1], tempfile.mkdtemp())
    >>> len(key), data[:2]
    (64, b'PK')
    """
    from ..morphing.preprocess import _compute_pair

    local = local_bank(pack, cache)
    bank, store = local.bank, local.store
    nb = local.normalised()
    key = store.pair_key(bank, a, b, nb.axis)
    # An entry already on this machine (an earlier batch) is shipped as it is, unchecked:
    # every store checks each entry it reads, so a damaged one becomes a miss wherever it
    # lands and is recomputed there. Checking here too would cost a decode per pair.
    if not store.pair_path(key).is_file():
        _compute_pair(str(store.root), key, nb, a, b)
    with local.lock:
        local.installed.add(key)
    return key, store.pair_path(key).read_bytes()


def clip_task(task: ClipTask, pack: BankPack, entries: List[Tuple[str, bytes]],
              cache: Optional[str] = None) -> dict:
    """Render one clip; returns ``{"ok": True, "data": mp4 bytes, ...}`` or ``{"ok": False, "error": ...}``.

    Parameters
    ----------
    task : ClipTask
        Options and input files.
    pack : BankPack
        The bank.
    entries : list of (str, bytes)
        The bank's flow store entries (the results of its :func:`pair_task` tasks).
    cache : str, optional
        This machine's cache folder.

    Examples
    --------
    >>> import tempfile
    >>> from lipsync._data import default_bank_dir
    >>> from lipsync.batch import pack_bank
    >>> from lipsync.morphing.preprocess import all_pairs
    >>> pack, cache = pack_bank(default_bank_dir()), tempfile.mkdtemp()
    >>> entries = [pair_task(pack, a, b, cache) for a, b in all_pairs(pack.names)]  # doctest: +SKIP
    >>> cues = b"0.00\\tX\\n0.40\\tD\\n0.80\\tX\\n"
    >>> task = ClipTask(line=2, output="a.mp4", files={"input": ("a.tsv", cues, "a.tsv")}, text=None,
    ...                 fps=25.0, map="english-to-rhubarb", timing="linear", method="flow")
    >>> result = clip_task(task, pack, entries, cache)                               # doctest: +SKIP
    >>> result["ok"], result["frames"], result["data"][4:8]                          # doctest: +SKIP
    (True, 20, b'ftyp')
    """
    from .. import __version__
    from ..pipeline.clip import render_clip

    t0 = time.perf_counter()
    result = {"line": task.line, "version": __version__, "host": os.uname().nodename, "pid": os.getpid()}
    cache_dir = Path(cache) if cache is not None else default_cache_dir()
    work = None
    names: Dict[str, str] = {}
    try:
        local = local_bank(pack, cache_dir)
        install_entries(local, entries)
        work = _work_folder(cache_dir)
        paths: Dict[str, str] = {}
        for role, (name, data, client_path) in task.files.items():
            p = work / role / name
            p.parent.mkdir()
            p.write_bytes(data)
            paths[role] = str(p)
            names[str(p)] = client_path
        out = work / "out" / Path(task.output).name
        out.parent.mkdir()
        report = render_clip(paths["input"], out, bank=local.bank, store=local.store, audio=paths.get("audio"),
                             fps=task.fps, map=paths.get("map", task.map), method=task.method,
                             timing=task.timing or None, quiet=True, jobs=1,
                             timeline_options=TimelineOptions(text=paths.get("text", task.text)))
        result.update(ok=True, data=out.read_bytes(), frames=report.frames, fps=report.fps,
                      seconds=report.duration, render_seconds=time.perf_counter() - t0)
    except Exception as exc:  # a bad clip is a report row; the batch goes on
        message = f"{type(exc).__name__}: {exc}"
        for worker_path, client_path in names.items():  # name the user's file, not our copy
            message = message.replace(worker_path, client_path)
        result.update(ok=False, error=message, render_seconds=time.perf_counter() - t0)
    finally:
        if work is not None:
            shutil.rmtree(work, ignore_errors=True)
    return result
