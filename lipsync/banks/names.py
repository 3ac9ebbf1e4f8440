"""Viseme names from image file names, for ``lipsync init``.

Three naming systems are in common use for mouth drawings; a folder is read in the first
system that names every image exactly once. A file name counts when one of its parts (split
at ``-``, ``_``, spaces and dots) is a name of the system, ignoring case: ``mouth_A.png``,
``lisa-MBP.png`` and ``viseme.kk.jpg`` all work.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

from ..errors import InputError

#: Naming systems, in the order they are tried (the first that fits every file wins, so a
#: folder of A..H X, whose "E" the others also know, reads as Rhubarb).
#: Each maps its names to the shipped toon's viseme whose control lines start it off, and
#: names its rest shape.
SYSTEMS: Dict[str, Dict[str, str]] = {
    # Rhubarb Lip Sync's mouth shapes are the toon's own.
    "rhubarb": {n: n for n in "ABCDEFGHX"},
    # Preston Blair's set, as in Papagayo-NG and Moho; their Rhubarb twins per the aliases
    # of configs/maps/english-to-rhubarb.yaml.
    "preston-blair": {"MBP": "A", "etc": "B", "E": "C", "AI": "D", "O": "E", "U": "F", "WQ": "F",
                      "FV": "G", "L": "H", "rest": "X"},
    # The 15 Oculus (Meta) Lipsync visemes, each started from the Rhubarb shape nearest in
    # mouth opening and rounding (by the phones each stands for).
    "oculus": {
        "sil": "X",   # silence
        "PP": "A",    # p b m: lips closed
        "FF": "G",    # f v: upper teeth on lower lip
        "TH": "H",    # th: tongue between the teeth, slightly open
        "DD": "B",    # t d: teeth nearly together
        "kk": "B",    # k g: slightly open
        "CH": "B",    # ch j sh: teeth together, lips forward
        "SS": "B",    # s z: teeth together
        "nn": "B",    # n l: slightly open
        "RR": "E",    # r: rounded
        "aa": "D",    # a: wide open
        "E": "C",     # e: open
        "I": "B",     # i: spread, nearly closed
        "O": "E",     # o: rounded open
        "U": "F",     # u: puckered
    },
}
#: Other spellings of Oculus names seen in exported sprite sets.
OCULUS_SPELLINGS = {"ih": "I", "oh": "O", "ou": "U"}
REST = {"rhubarb": "X", "preston-blair": "rest", "oculus": "sil"}

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


def _parts(stem: str) -> List[str]:
    return [p for p in re.split(r"[-_ .]+", stem) if p]


def _match(stem: str, system: str) -> List[str]:
    """The system's names among a file stem's parts (each at most once)."""
    table = SYSTEMS[system]
    lower = {n.lower(): n for n in table}
    if system == "oculus":
        lower.update({k: v for k, v in OCULUS_SPELLINGS.items()})
    found = []
    for part in _parts(stem):
        name = lower.get(part.lower())
        if name is not None and name not in found:
            found.append(name)
    return found


def parse_names_option(values: Sequence[str]) -> Dict[str, str]:
    """``--names`` values (``FILE=VISEME``, comma-separated or repeated) → {file stem: viseme}.

    Examples
    --------
    >>> parse_names_option(["closed=M, open.png=O", "smile=E"])
    {'closed': 'M', 'open': 'O', 'smile': 'E'}
    """
    out: Dict[str, str] = {}
    for value in values:
        for item in value.split(","):
            item = item.strip()
            if not item:
                continue
            if "=" not in item:
                raise InputError(f"--names: expected FILE=VISEME, got {item!r}")
            file, viseme = (s.strip() for s in item.split("=", 1))
            stem = Path(file).stem if Path(file).suffix.lower() in IMAGE_SUFFIXES else file
            if not stem or not re.match(r"^[A-Za-z0-9_.+-]{1,64}$", viseme):
                raise InputError(f"--names: {item!r}: viseme names use letters, digits and _ . + - only")
            out[stem] = viseme
    return out


def name_images(files: Sequence[Path], explicit: Optional[Dict[str, str]] = None
                ) -> Tuple[Dict[str, Path], Optional[str]]:
    """Viseme name for each image file, and the naming system used (None: ``--names`` only).

    Files named in ``explicit`` (by stem) take that name; the rest must all fit one system.

    Raises
    ------
    InputError
        Naming the files no system recognises, or two files that give one name.

    Examples
    --------
    >>> from pathlib import Path
    >>> named, system = name_images([Path("m_A.png"), Path("m_X.png"), Path("m_D.png")])
    >>> system, sorted(named)
    ('rhubarb', ['A', 'D', 'X'])
    >>> name_images([Path("MBP.png"), Path("rest.png")])[1]
    'preston-blair'
    """
    explicit = dict(explicit or {})
    unknown_stems = set(explicit) - {f.stem for f in files}
    if unknown_stems:
        raise InputError(f"--names: no image called {sorted(unknown_stems)[0]!r} in the folder")
    rest_files = [f for f in files if f.stem not in explicit]
    chosen, matches = None, {}
    for system in SYSTEMS:
        found = {f: _match(f.stem, system) for f in rest_files}
        if all(len(m) == 1 for m in found.values()):
            chosen, matches = system, {f: m[0] for f, m in found.items()}
            break
    if chosen is None and rest_files:
        best = max(SYSTEMS, key=lambda s: sum(len(_match(f.stem, s)) == 1 for f in rest_files))
        bad = [f.name for f in rest_files if len(_match(f.stem, best)) != 1]
        raise InputError(
            f"cannot tell which viseme {len(bad)} image(s) show: {', '.join(bad[:6])}"
            f"{' ...' if len(bad) > 6 else ''}. File names are read as Rhubarb (A-H, X), Preston Blair "
            f"(MBP, etc, E, AI, O, U, WQ, FV, L, rest) or Oculus (sil, PP, FF, TH, DD, kk, CH, SS, nn, RR, "
            f"aa, E, I, O, U) names; map others with --names FILE=VISEME", path=bad[0])
    named: Dict[str, Path] = {}
    for f in files:
        v = explicit.get(f.stem) or matches[f]
        if v in named:
            raise InputError(f"images {named[v].name!r} and {f.name!r} both give viseme {v!r}; "
                             f"rename one or use --names", path=f)
        named[v] = f
    return named, chosen
