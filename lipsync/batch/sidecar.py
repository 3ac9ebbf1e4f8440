"""Stage 2 of a batch: which clips are already done (black's cache.py style).

A clip's key is a sha256 of everything its video depends on: the lipsync version, the
bytes of its input, audio, transcript and map files (or the names given), the bank pack's
digest and every option. Beside each output ``name.mp4`` a sidecar
``name.mp4.lipsync.json`` records the key and the output's sha256 and size; a row is
skipped when both match. A missing, unreadable or foreign sidecar, or an output that was
changed or cut, is simply "not done" (the clip is rendered again). The sidecar is written
after the output, each atomically, so a sidecar never vouches for a half-written file.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Optional

from ..pipeline.clip import DEFAULT_CRF, DEFAULT_PRESET
from .manifest import SIDECAR_SUFFIX, ClipJob

_CHUNK = 1 << 20


def file_sha256(path: os.PathLike) -> str:
    """sha256 of a file's bytes (read in 1 MB chunks).

    Examples
    --------
    >>> import os, tempfile
    >>> p = os.path.join(tempfile.mkdtemp(), "f")
    >>> _ = open(p, "wb").write(b"abc")
    >>> file_sha256(p)[:16]
    'ba7816bf8f01cfea'
    """
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(_CHUNK), b""):
            h.update(chunk)
    return h.hexdigest()


def clip_key(job: ClipJob, bank_digest: str) -> str:
    """The content key of a clip: same key, same video.

    Examples
    --------
    >>> import os, tempfile
    >>> from pathlib import Path
    >>> from lipsync.batch.manifest import ClipJob
    >>> p = Path(tempfile.mkdtemp()) / "a.tsv"
    >>> _ = p.write_text("0.00\\tX\\n0.40\\tX\\n")
    >>> job = ClipJob(line=2, input=p, output="a.mp4", bank=Path("."), map="rhubarb", timing="linear")
    >>> clip_key(job, "b" * 64) == clip_key(job, "b" * 64) != clip_key(job, "c" * 64)
    True
    """
    from .. import __version__

    parts = {
        "lipsync": __version__,
        "bank": bank_digest,
        "input": file_sha256(job.input),
        "audio": file_sha256(job.audio) if job.audio else None,
        "text": ("file", file_sha256(job.text_file)) if job.text_file else job.text,
        "map": ("file", file_sha256(job.map_file)) if job.map_file else job.map,
        # The input's extension picks its reader, so it is part of what the clip means.
        "input_ext": job.input.suffix.lower(),
        "output_ext": Path(job.output).suffix.lower(),
        "fps": repr(float(job.fps)),
        "timing": job.timing,
        "method": job.method,
        "crf": DEFAULT_CRF,
        "preset": DEFAULT_PRESET,
    }
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()


def sidecar_path(output: Path) -> Path:
    """The sidecar beside ``output``.

    Examples
    --------
    >>> sidecar_path(Path("out/a.mp4")).as_posix()
    'out/a.mp4.lipsync.json'
    """
    return output.with_name(output.name + SIDECAR_SUFFIX)


def read_done(output: Path, key: str) -> Optional[dict]:
    """The sidecar of ``output`` if it vouches for the current file and ``key``; else None.

    Examples
    --------
    >>> import tempfile
    >>> out = Path(tempfile.mkdtemp()) / "a.mp4"
    >>> write_done(out, b"video", "k" * 64, {"frames": 5})
    >>> read_done(out, "k" * 64)["frames"], read_done(out, "j" * 64)
    (5, None)
    """
    try:
        meta = json.loads(sidecar_path(output).read_text(encoding="utf-8"))
        if not isinstance(meta, dict) or meta.get("key") != key:
            return None
        if output.stat().st_size != meta.get("output_bytes") or file_sha256(output) != meta.get("output_sha256"):
            return None
        return meta
    except (OSError, ValueError):
        return None


def write_done(output: Path, data: bytes, key: str, info: dict) -> None:
    """Write the video then its sidecar, each through a temporary file renamed into place."""
    from .._files import atomic_write_bytes

    atomic_write_bytes(output, lambda fh: fh.write(data))
    meta = dict(info, key=key, output_bytes=len(data), output_sha256=hashlib.sha256(data).hexdigest())
    text = json.dumps(meta, indent=1, sort_keys=True) + "\n"
    atomic_write_bytes(sidecar_path(output), lambda fh: fh.write(text.encode()))
