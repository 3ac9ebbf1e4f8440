"""The two JSON files an engine reads: the atlas (``mouth.json``) and its frames (``frames.json``).

Atlas, ``"format": "lipsync-atlas"``, ``"version": 1``::

    {
      "format": "lipsync-atlas", "version": 1,
      "image": "mouth.png",            texture, relative to this file (RGBA PNG)
      "image_size": [W, H],            texture size in pixels
      "base": "mouth.base.png",        or null: draw it first, then one cell (see below)
      "frame_size": [w, h],            the frame the bank renders, in frame pixels
      "region": [x, y, w, h],          where every cell goes in the frame (frame pixels)
      "scale": 1.0,                    texture pixels per frame pixel (cells and base)
      "padding": 2,                    pixels around each cell repeating its edge (filtering)
      "bank": "toon", "rest": "X",     the subject and its rest viseme
      "visemes": ["A", ..., "X"],      the bank's visemes, in the bank's order
      "method": "flow",                how the in-betweens were rendered
      "inbetweens": 3,                 in-betweens per pair, at alpha k / (inbetweens + 1)
      "cells": [                       cell i is cells[i]; frames.json names cells by i
        {"rect": [x, y, w, h], "from": "A", "to": "A", "alpha": 0.0},   a viseme
        {"rect": [...], "from": "A", "to": "B", "alpha": 0.25},          an in-between
        ...
      ]
    }

Drawing frame content: the base image (``frame_size * scale`` pixels; the whole frame, clear
inside ``region``) scaled to the frame, then the cell's ``rect`` of the texture drawn into
``region``. Outside ``region`` every frame of the bank is the same picture, so the cells hold
only the part that changes (for the shipped toon 306 x 251 of 512 x 512 pixels, a third).
Viseme cells come first (``from == to``, ``alpha`` 0), then the in-betweens of each pair in
order of alpha; a pair is stored in one direction (``from`` before ``to`` in ``visemes``):
the morph from B to A at alpha is the one from A to B at ``1 - alpha``.

Frames, ``"format": "lipsync-atlas-frames"``, ``"version": 1``::

    {
      "format": "lipsync-atlas-frames", "version": 1,
      "atlas": "mouth.json",           the atlas, relative to this file
      "fps": 30, "duration": 2.97,     frame n shows the time [n / fps, (n + 1) / fps)
      "count": 90,
      "frames": [0, 0, 7, 8, 1, ...],  the cell of each frame
      "missing_pairs": [["A", "D"]]    morphs the atlas lacks (shown as the nearer viseme)
    }

An engine plays it on its own clock: ``n = floor(t * fps)`` (the last frame after the end),
draw ``cells[frames[n]]``. A reader refuses a ``version`` newer than it knows; a newer
lipsync adds fields within a version only when older readers may ignore them.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple, Union

from .._files import load_json, read_input_bytes
from ..errors import InputError

PathLike = Union[str, "os.PathLike[str]"]

ATLAS_FORMAT = "lipsync-atlas"
FRAMES_FORMAT = "lipsync-atlas-frames"
#: Version of both documents. Bump it when a field changes meaning or a reader must not
#: ignore a new one.
SCHEMA_VERSION = 1
#: Largest atlas JSON read: a 16384-px texture of 16x16 cells holds a million cells, and
#: even that is ~80 MB of JSON; 64 MB keeps a wrong file from being read whole.
MAX_JSON_BYTES = 64 << 20


@dataclass(frozen=True)
class Cell:
    """One cell: its rectangle in the texture and the frame it holds (``from -> to`` at ``alpha``)."""

    rect: Tuple[int, int, int, int]
    from_viseme: str
    to_viseme: str
    alpha: float

    @property
    def viseme(self) -> Optional[str]:
        """The viseme shown exactly, or None for an in-between."""
        return self.from_viseme if self.from_viseme == self.to_viseme or self.alpha == 0.0 else None


@dataclass(frozen=True)
class Atlas:
    """A sprite atlas as described by its JSON (see the module notes for the fields).

    Examples
    --------
    >>> a = Atlas(image="m.png", image_size=(8, 4), base=None, frame_size=(4, 4), region=(0, 0, 4, 4),
    ...           scale=1.0, padding=0, bank="b", rest="X", visemes=("A", "X"), method="flow",
    ...           inbetweens=0, cells=(Cell((0, 0, 4, 4), "A", "A", 0.0), Cell((4, 0, 4, 4), "X", "X", 0.0)))
    >>> Atlas.from_dict(json.loads(json.dumps(a.to_dict()))) == a
    True
    >>> a.viseme_cells()
    {'A': 0, 'X': 1}
    """

    image: str
    image_size: Tuple[int, int]
    base: Optional[str]
    frame_size: Tuple[int, int]
    region: Tuple[int, int, int, int]
    scale: float
    padding: int
    bank: str
    rest: str
    visemes: Tuple[str, ...]
    method: str
    inbetweens: int
    cells: Tuple[Cell, ...]
    path: Optional[str] = None

    def to_dict(self) -> dict:
        """The JSON document (fields in the documented order)."""
        return {
            "format": ATLAS_FORMAT, "version": SCHEMA_VERSION,
            "image": self.image, "image_size": list(self.image_size), "base": self.base,
            "frame_size": list(self.frame_size), "region": list(self.region), "scale": self.scale,
            "padding": self.padding, "bank": self.bank, "rest": self.rest, "visemes": list(self.visemes),
            "method": self.method, "inbetweens": self.inbetweens,
            "cells": [{"rect": list(c.rect), "from": c.from_viseme, "to": c.to_viseme, "alpha": c.alpha}
                      for c in self.cells],
        }

    def to_json(self) -> str:
        """The JSON text: one line per cell, so diffs and people can read it."""
        d = self.to_dict()
        cells = d.pop("cells")
        rows = ",\n".join("    " + json.dumps(c) for c in cells)
        return f'{{\n{_fields(d)},\n  "cells": [\n{rows}\n  ]\n}}\n'

    def viseme_cells(self) -> Dict[str, int]:
        """Viseme -> index of its cell."""
        return {c.from_viseme: i for i, c in enumerate(self.cells) if c.viseme is not None}

    def pair_cells(self) -> Dict[Tuple[str, str], List[Tuple[float, int]]]:
        """(from, to) as stored -> [(alpha, cell index)] from alpha 0 (``from``) to 1 (``to``)."""
        vis = self.viseme_cells()
        pairs: Dict[Tuple[str, str], List[Tuple[float, int]]] = {}
        for i, c in enumerate(self.cells):
            if c.viseme is None:
                pairs.setdefault((c.from_viseme, c.to_viseme), []).append((c.alpha, i))
        for (a, b), cells in pairs.items():
            cells.sort()
            cells.insert(0, (0.0, vis[a]))
            cells.append((1.0, vis[b]))
        return pairs

    @classmethod
    def from_dict(cls, doc, path: Optional[PathLike] = None) -> "Atlas":
        """Check a parsed atlas JSON and make an Atlas; InputError naming the file and field."""
        where = os.fspath(path) if path is not None else None

        def fail(msg: str):
            raise InputError(msg, path=where)

        if not isinstance(doc, dict) or doc.get("format") != ATLAS_FORMAT:
            fail(f"not a lipsync atlas (\"format\" must be {ATLAS_FORMAT!r}; write one with `lipsync atlas`)")
        version = doc.get("version")
        if not isinstance(version, int) or isinstance(version, bool) or version < 1:
            fail(f"\"version\" must be a whole number, got {version!r}")
        if version > SCHEMA_VERSION:
            fail(f"atlas version {version} is newer than this lipsync reads ({SCHEMA_VERSION}); update lipsync")

        def ints(key, n, low=0):
            v = doc.get(key)
            if (not isinstance(v, list) or len(v) != n
                    or not all(isinstance(x, int) and not isinstance(x, bool) and low <= x <= 1 << 20 for x in v)):
                fail(f"\"{key}\" must be {n} whole numbers from {low} to {1 << 20}, got {v!r}")
            return tuple(v)

        def text(key, optional=False):
            v = doc.get(key)
            if v is None and optional:
                return None
            if not isinstance(v, str) or not v:
                fail(f"\"{key}\" must be a non-empty string, got {v!r}")
            return v

        image, base = text("image"), text("base", optional=True)
        for name, value in (("image", image), ("base", base)):
            if value is not None and (os.path.isabs(value) or ".." in Path(value).parts):
                fail(f"\"{name}\" must be a file beside the atlas, not {value!r}")
        image_size, frame_size = ints("image_size", 2, 1), ints("frame_size", 2, 1)
        region = ints("region", 4)
        rx, ry, rw, rh = region
        if rw < 1 or rh < 1 or rx + rw > frame_size[0] or ry + rh > frame_size[1]:
            fail(f"\"region\" {list(region)} is not inside the frame {list(frame_size)}")
        scale = doc.get("scale")
        if not isinstance(scale, (int, float)) or isinstance(scale, bool) or not (0 < scale <= 1) \
                or not math.isfinite(scale):
            fail(f"\"scale\" must be a number in (0, 1], got {scale!r}")
        padding = doc.get("padding")
        if not isinstance(padding, int) or isinstance(padding, bool) or not 0 <= padding <= 64:
            fail(f"\"padding\" must be a whole number 0..64, got {padding!r}")
        inbetweens = doc.get("inbetweens")
        if not isinstance(inbetweens, int) or isinstance(inbetweens, bool) or not 0 <= inbetweens <= 1000:
            fail(f"\"inbetweens\" must be a whole number 0..1000, got {inbetweens!r}")
        visemes = doc.get("visemes")
        if (not isinstance(visemes, list) or not visemes or not all(isinstance(v, str) and v for v in visemes)
                or len(set(visemes)) != len(visemes)):
            fail(f"\"visemes\" must be a list of distinct names, got {visemes!r}")
        rest = text("rest")
        if rest not in visemes:
            fail(f"\"rest\" {rest!r} is not one of the visemes")
        raw_cells = doc.get("cells")
        if not isinstance(raw_cells, list) or not raw_cells:
            fail("\"cells\" must be a non-empty list")
        cells: List[Cell] = []
        for i, c in enumerate(raw_cells):
            if not isinstance(c, dict):
                fail(f"cell {i} must be an object")
            rect = c.get("rect")
            if (not isinstance(rect, list) or len(rect) != 4
                    or not all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in rect)):
                fail(f"cell {i}: \"rect\" must be 4 whole numbers, got {rect!r}")
            x, y, w, h = rect
            if w < 1 or h < 1 or x + w > image_size[0] or y + h > image_size[1]:
                fail(f"cell {i}: \"rect\" {rect} is not inside the texture {list(image_size)}")
            a, b, alpha = c.get("from"), c.get("to"), c.get("alpha")
            if a not in visemes or b not in visemes:
                fail(f"cell {i}: \"from\" and \"to\" must be visemes of the atlas, got {a!r}, {b!r}")
            if (not isinstance(alpha, (int, float)) or isinstance(alpha, bool) or not math.isfinite(alpha)
                    or not 0 <= alpha < 1 or (a == b) != (alpha == 0)):
                fail(f"cell {i}: \"alpha\" must be 0 for a viseme and in (0, 1) for an in-between, got {alpha!r}")
            cells.append(Cell(tuple(rect), a, b, float(alpha)))
        shown = {c.from_viseme for c in cells if c.viseme is not None}
        if shown != set(visemes) or len(shown) != sum(c.viseme is not None for c in cells):
            fail("there must be exactly one cell for each viseme")
        return cls(image=image, image_size=image_size, base=base, frame_size=frame_size, region=region,
                   scale=float(scale), padding=padding, bank=text("bank"), rest=rest, visemes=tuple(visemes),
                   method=text("method"), inbetweens=inbetweens, cells=tuple(cells), path=where)


def load_atlas(path: PathLike) -> Atlas:
    """Read and check an atlas JSON written by ``lipsync atlas``.

    Raises
    ------
    InputError
        The file is missing, not JSON, not an atlas, or a field is wrong (the message names
        the file and the field).
    """
    p = Path(os.fspath(path))
    data = read_input_bytes(p, "an atlas JSON file", limit=MAX_JSON_BYTES)
    if len(data) > MAX_JSON_BYTES:
        raise InputError(f"larger than {MAX_JSON_BYTES >> 20} MB: not an atlas", path=p)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"not valid JSON ({exc})", path=p) from None
    return Atlas.from_dict(load_json(text, p), p)  # nesting bounded: no RecursionError


def frames_document(atlas_ref: str, fps: float, duration: float, frames: Sequence[int],
                    missing_pairs: Sequence[Tuple[str, str]]) -> str:
    """The frames.json text (one line of frame numbers: it is data for engines, not people)."""
    head = {"format": FRAMES_FORMAT, "version": SCHEMA_VERSION, "atlas": atlas_ref, "fps": fps,
            "duration": round(float(duration), 6), "count": len(frames)}
    return (f'{{\n{_fields(head)},\n  "frames": {json.dumps(list(frames), separators=(",", ":"))},\n'
            f'  "missing_pairs": {json.dumps([list(p) for p in missing_pairs])}\n}}\n')


def _fields(d: dict) -> str:
    """One ``"key": value`` line per field, lists kept on their line."""
    return ",\n".join(f"  {json.dumps(k)}: {json.dumps(v)}" for k, v in d.items())
