"""Where the shipped data lives: the default subject (visemes/) and maps (configs/).

In a checkout (editable install) they are the top-level folders beside the package; in an
installed wheel setuptools copies them into the package as ``_visemes`` and ``_configs``.
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


def data_dir(kind: str) -> Path:
    """The folder holding shipped data of ``kind`` ("visemes" or "configs")."""
    for candidate in (_PACKAGE / f"_{kind}", _PACKAGE.parent / kind):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"lipsync's {kind}/ data folder is missing from the installation")


DEFAULT_BANK_NAME = "toon"


def default_bank_dir() -> Path:
    """The default subject's bank folder."""
    return data_dir("visemes") / DEFAULT_BANK_NAME


def shipped_banks() -> dict:
    """The subjects shipped with lipsync: name -> bank folder (those holding a bank.yaml).

    Examples
    --------
    >>> sorted(shipped_banks())
    ['grid-s1', 'toon']
    """
    root = data_dir("visemes")
    return {p.name: p for p in sorted(root.iterdir()) if (p / "bank.yaml").is_file()}
