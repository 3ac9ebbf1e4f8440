"""Step 8: the bank on disk — all of it or nothing.

Everything (PNGs, bank.yaml, the report, the preview sheet, the flows) is written into a
hidden temporary folder beside ``OUTDIR`` and renamed into place only when complete
(:class:`Staging`): a failure, a full disk or Ctrl-C part-way leaves ``OUTDIR`` as it was
(absent, empty, or the previous bank), never a half-written bank. A rename within one
folder is atomic; replacing a previous bank (``--force``) moves it aside first and removes
it after the new one is in place.

Examples
--------
>>> import tempfile, pathlib
>>> root = pathlib.Path(tempfile.mkdtemp())
>>> with Staging(root / "me") as tmp:
...     _ = (tmp / "bank.yaml").write_text("x")
>>> sorted(p.name for p in root.iterdir()), (root / "me" / "bank.yaml").read_text()
(['me'], 'x')
"""

from __future__ import annotations

import json
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Dict, List, Mapping, Optional

import numpy as np

from ..errors import InputError

#: The report and the preview sheet, written beside bank.yaml.
REPORT_NAME = "init-report.json"
PREVIEW_NAME = "preview.png"
#: Width of one tile of the preview sheet (as ``lipsync preview``'s): line names stay legible.
PREVIEW_TILE = 320
#: Viseme names that are safe as file names on every system; others get ``viseme-N.png``.
_SAFE_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")


def check_outdir(outdir: Path, force: bool) -> None:
    """Refuse an output that is a file, or a non-empty folder without ``force`` (before any work)."""
    if outdir.exists() and not outdir.is_dir():
        raise InputError("exists and is not a folder", path=outdir)
    if outdir.is_dir() and any(outdir.iterdir()) and not force:
        raise InputError("is not empty; use --force to replace what is there with the new bank", path=outdir)


class Staging:
    """A temporary folder beside ``outdir`` that becomes ``outdir`` when the block succeeds."""

    def __init__(self, outdir: Path, *, force: bool = False):
        self.outdir = Path(outdir)
        self.force = force
        self.tmp: Optional[Path] = None

    def __enter__(self) -> Path:
        check_outdir(self.outdir, self.force)
        parent = self.outdir.resolve().parent
        parent.mkdir(parents=True, exist_ok=True)
        self.tmp = Path(tempfile.mkdtemp(prefix=f".{self.outdir.name}.tmp-", dir=parent))
        os.chmod(self.tmp, 0o755)  # mkdtemp's folder is private; a bank is meant to be shared
        return self.tmp

    def __exit__(self, exc_type, exc, tb) -> bool:
        assert self.tmp is not None
        if exc_type is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            return False
        try:
            self._commit()
        except BaseException:
            shutil.rmtree(self.tmp, ignore_errors=True)
            raise
        return False

    def _commit(self) -> None:
        check_outdir(self.outdir, self.force)  # again: it may have changed meanwhile
        old = None
        if self.outdir.is_dir():
            if any(self.outdir.iterdir()):
                old = Path(tempfile.mkdtemp(prefix=f".{self.outdir.name}.old-", dir=self.tmp.parent))
                os.rename(self.outdir, old / "bank")
            else:
                self.outdir.rmdir()
        os.rename(self.tmp, self.outdir)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


def image_names(visemes: List[str]) -> Dict[str, str]:
    """Viseme → PNG file name (its own name when safe and unique ignoring case).

    Examples
    --------
    >>> image_names(["X", "A", "a/b", "x"])
    {'X': 'X.png', 'A': 'A.png', 'a/b': 'viseme-3.png', 'x': 'viseme-4.png'}
    """
    out, taken = {}, set()
    for i, v in enumerate(visemes, 1):
        name = f"{v}.png" if _SAFE_NAME.fullmatch(v) and v.lower() not in taken else f"viseme-{i}.png"
        taken.add(v.lower())
        out[v] = name
    return out


def bank_text(name: str, rest: str, files: Mapping[str, str], features: Mapping[str, Mapping], *,
              symmetric: bool, header: List[str], timing: Optional[str] = None,
              coarticulation: Optional[Mapping] = None) -> str:
    """bank.yaml text for the chosen pictures and their face lines (and, when given, how the
    mouth moves: bank.yaml's ``timing`` and the speaker's fitted ``coarticulation``)."""
    from ..banks.yamlio import dump_bank
    from ..face.lines import FACE_WARP

    doc = {"name": name, "rest": rest, "warp": {"a": FACE_WARP.a, "b": FACE_WARP.b, "p": FACE_WARP.p},
           "symmetry": bool(symmetric)}
    if timing is not None:
        doc["timing"] = timing
    if coarticulation is not None:
        doc["coarticulation"] = dict(coarticulation)
    doc["visemes"] = {v: {"image": files[v], "lines": {n: f.to_yaml_value() for n, f in features[v].items()}}
                      for v in files}
    return dump_bank(doc, header=header)


def write_png(path: Path, rgb: np.ndarray) -> None:
    from ..preview import save_png

    save_png(path, rgb)


def write_report(path: Path, report: dict) -> None:
    from .._files import atomic_write_bytes

    data = (json.dumps(report, indent=2, ensure_ascii=False) + "\n").encode("utf-8")
    atomic_write_bytes(path, lambda fh: fh.write(data))


def write_preview(path: Path, bank) -> None:
    """The preview sheet (``lipsync preview``'s): every viseme with its lines and names."""
    from ..preview import feature_lines, preview_sheet, save_png

    named = {v: feature_lines(bank.line_names, bank.lines[v]) for v in bank.names}
    save_png(path, preview_sheet({v: bank.images[v] for v in bank.names}, named,
                                 tile=min(PREVIEW_TILE, bank.shape[1])))
