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
from typing import Dict, List, Mapping, Optional, Sequence

import numpy as np

from ..errors import InputError, PathLike
from .._files import WRITE_ERRORS

#: The report and the preview sheet, written beside bank.yaml.
REPORT_NAME = "init-report.json"
PREVIEW_NAME = "preview.png"
#: Width of one tile of the preview sheet (as ``lipsync preview``'s): line names stay legible.
PREVIEW_TILE = 320
#: Viseme names that are safe as file names on every system; others get ``viseme-N.png``.
_SAFE_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")


def check_outdir(outdir: Path, force: bool, inputs: Sequence[PathLike] = ()) -> None:
    """Refuse, before any work, an ``outdir`` the new bank may not replace.

    The bank replaces the whole folder, so: never the current folder or one holding it,
    nor a folder holding one of ``inputs`` (the videos and transcripts it is made from); a
    file; a non-empty folder without ``force``; and with ``force`` only a folder that is a
    bank (has ``bank.yaml``) -- never anyone's other files.
    """
    try:
        _check_outdir(outdir, force, inputs)
    except OSError as exc:  # a name too long, a file on the path, no permission to look
        raise write_error(exc, outdir) from None


def _check_outdir(outdir: Path, force: bool, inputs: Sequence[PathLike]) -> None:
    if outdir.exists() and not outdir.is_dir():
        raise InputError("exists and is not a folder", path=outdir)
    where = _resolved(outdir)
    here = _resolved(Path.cwd())
    if where == here or where in here.parents:
        raise InputError("is the current folder (or holds it); the bank replaces the whole folder: give a new "
                         "folder's name", path=outdir)
    for item in inputs:
        p = _resolved(Path(os.fspath(item)))
        if p == where or where in p.parents:
            raise InputError(f"holds {item}, an input of this bank; the bank replaces the whole folder: give "
                             f"another folder", path=outdir)
    if outdir.is_dir() and any(outdir.iterdir()):
        if not (outdir / "bank.yaml").is_file():
            raise InputError("is not empty and is not a bank (no bank.yaml); --force replaces only a bank: give a "
                             "new or empty folder", path=outdir)
        if not force:
            raise InputError("holds a bank; use --force to replace it with the new bank", path=outdir)


def _resolved(p: Path) -> Path:
    try:
        return p.resolve()
    except (OSError, RuntimeError):  # a symlink loop: compare it as written
        return Path(os.path.abspath(p))




def write_error(exc: OSError, outdir: Path) -> Exception:
    """``exc`` as an error naming ``outdir``: an InputError (exit 2) for the errnos of
    :data:`WRITE_ERRORS`, else an OSError naming ``outdir``.

    Examples
    --------
    >>> str(write_error(OSError(28, "No space left on device", "/x/.me.partial-1-ab/C.png"), Path("me")))
    'me: cannot write the bank: the disk is full (nothing was written)'
    """
    reason = WRITE_ERRORS.get(exc.errno)
    if reason is None:
        return type(exc)(exc.errno, f"cannot write the bank {outdir}: {exc.strerror or exc}")
    return InputError(f"cannot write the bank: {reason} (nothing was written)", path=outdir)


def check_writable(outdir: Path) -> None:
    """Before any work: remove what killed runs left beside ``outdir`` and prove a staging
    folder can be made there (read-only disks, a file in the path, a name too long fail now,
    not after minutes of work). Folders made for the proof are removed again: a run that
    fails later leaves nothing."""
    missing = []
    parent = _resolved(Path(outdir)).parent
    while not parent.exists() and parent != parent.parent:
        missing.append(parent)
        parent = parent.parent
    try:
        os.rmdir(Staging(outdir)._make_tmp())
    finally:
        for folder in missing:  # deepest first
            try:
                folder.rmdir()
            except OSError:
                pass


class Staging:
    """A temporary folder beside ``outdir`` that becomes ``outdir`` when the block succeeds.

    Named ``.OUT.partial-PID-XXXX`` (:func:`lipsync._files.partial_name`), so the next run
    removes it if this process is killed (:func:`lipsync._files.remove_stale_partials`);
    the previous bank moved aside by ``--force`` is ``.OUT.old-PID-XXXX``, removed the same
    way once OUT exists again. Errors name OUT (:func:`write_error`).
    """

    def __init__(self, outdir: Path, *, force: bool = False, inputs: Sequence[PathLike] = ()):
        self.outdir = Path(outdir)
        self.force = force
        self.inputs = tuple(inputs)
        self.tmp: Optional[Path] = None

    def _make_tmp(self) -> Path:
        from .._files import partial_name, remove_stale_partials

        where = _resolved(self.outdir)
        try:
            where.parent.mkdir(parents=True, exist_ok=True)
            remove_stale_partials(where)
            if where.is_dir():  # a killed --force run had put the new bank in place
                remove_stale_partials(where, ("old",))
            self.tmp = Path(tempfile.mkdtemp(prefix=partial_name(where) + "-", dir=where.parent))
            os.chmod(self.tmp, 0o755)  # mkdtemp's folder is private; a bank is meant to be shared
        except OSError as exc:
            raise write_error(exc, self.outdir) from None
        return self.tmp

    def __enter__(self) -> Path:
        check_outdir(self.outdir, self.force, self.inputs)
        return self._make_tmp()

    def __exit__(self, exc_type, exc, tb) -> bool:
        assert self.tmp is not None
        if exc_type is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            if isinstance(exc, OSError):
                raise write_error(exc, self.outdir) from None
            return False
        try:
            self._commit()
        except BaseException as failed:
            shutil.rmtree(self.tmp, ignore_errors=True)
            if isinstance(failed, OSError):
                raise write_error(failed, self.outdir) from None
            raise
        return False

    def _commit(self) -> None:
        check_outdir(self.outdir, self.force, self.inputs)  # again: it may have changed meanwhile
        outdir = _resolved(self.outdir)
        old = None
        if outdir.is_dir():
            if any(outdir.iterdir()):
                old = Path(tempfile.mkdtemp(prefix=f".{outdir.name}.old-{os.getpid()}-", dir=self.tmp.parent))
                os.rename(outdir, old / "bank")
            else:
                outdir.rmdir()
        os.rename(self.tmp, outdir)
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
    from ..encode.preview import save_png

    save_png(path, rgb)


def write_report(path: Path, report: dict) -> None:
    from .._files import atomic_write_bytes

    data = (json.dumps(report, indent=2, ensure_ascii=False) + "\n").encode("utf-8")
    atomic_write_bytes(path, lambda fh: fh.write(data))


def write_preview(path: Path, bank) -> None:
    """The preview sheet (``lipsync preview``'s): every viseme with its lines and names."""
    from ..encode.preview import feature_lines, preview_sheet, save_png

    named = {v: feature_lines(bank.line_names, bank.lines[v]) for v in bank.names}
    save_png(path, preview_sheet({v: bank.images[v] for v in bank.names}, named,
                                 tile=min(PREVIEW_TILE, bank.shape[1])))
