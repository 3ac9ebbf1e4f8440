"""bank.yaml as people read it: block mappings, one control feature per line in flow style.

PyYAML's dumper would either sort keys or spread every point over three lines; a bank is a
fixed shape (DESIGN.md "Formats"), so it is written here field by field, in the order the
document gives, with every scalar checked to read back as itself. Comments at the top of a
file are kept on rewrite; comments elsewhere are not (PyYAML does not keep them).
"""

from __future__ import annotations

import functools
import json
import math
import os
import re
from pathlib import Path
from typing import Iterable, List, Mapping

import yaml

from .._files import atomic_write_bytes

_PLAIN = re.compile(r"^[A-Za-z_][A-Za-z0-9_.+-]*$")


def _scalar(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"not a finite number: {value!r}")
        return repr(value)  # the shortest text that reads back as the same float: no drift on rewrite
    return _string(str(value))


@functools.lru_cache(maxsize=4096)  # names repeat in every viseme; parsing each is the cost
def _string(text: str) -> str:
    # Plain when it reads back as the same string (not a bool, null or number in YAML 1.1).
    if _PLAIN.match(text) and yaml.safe_load(text) == text:
        return text
    return json.dumps(text, ensure_ascii=False)  # a JSON string is a YAML double-quoted scalar


def _flow(value) -> str:
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{_scalar(k)}: {_flow(v)}" for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_flow(v) for v in value) + "]"
    return _scalar(value)


def dump_bank(doc: Mapping, *, header: Iterable[str] = ()) -> str:
    """bank.yaml text for a bank document (the plain data ``yaml.safe_load`` gives).

    Parameters
    ----------
    doc : mapping
        ``name``, ``rest``, ``warp``, ``symmetry``, ``visemes`` (and whatever else it has,
        written in flow style) in the order to write them.
    header : iterable of str
        Comment lines for the top of the file (with or without the leading ``#``).

    Returns
    -------
    str

    Examples
    --------
    >>> doc = {"name": "me", "rest": "X", "visemes": {"X": {"image": "X.png",
    ...        "lines": {"lip": [[1, 2.5], [3, 4]], "arc": {"bezier": [[0, 0], [1, 1], [2, 1], [3, 0]]}}}}}
    >>> print(dump_bank(doc, header=["made by hand"]), end="")
    # made by hand
    name: me
    rest: X
    visemes:
      X:
        image: X.png
        lines:
          lip: [[1, 2.5], [3, 4]]
          arc: {bezier: [[0, 0], [1, 1], [2, 1], [3, 0]]}
    """
    out: List[str] = []
    for line in header:
        line = line.rstrip("\n")
        out.append(line if line.startswith("#") else ("# " + line).rstrip())
    for key, value in doc.items():
        if key == "visemes" and isinstance(value, Mapping):
            out.append("visemes:")
            for v, entry in value.items():
                if not isinstance(entry, Mapping):  # written as it is: the loader says what is wrong, at its line
                    out.append(f"  {_scalar(v)}: {_flow(entry)}")
                    continue
                out.append(f"  {_scalar(v)}:")
                for k2, v2 in entry.items():
                    if k2 == "lines" and isinstance(v2, Mapping):
                        out.append("    lines:")
                        out += [f"      {_scalar(n)}: {_flow(f)}" for n, f in v2.items()]
                    else:
                        out.append(f"    {_scalar(k2)}: {_flow(v2)}")
        else:
            out.append(f"{_scalar(key)}: {_flow(value)}")
    return "\n".join(out) + "\n"


def header_comments(text: str) -> List[str]:
    """The comment lines at the very top of a YAML text (kept when a bank is rewritten).

    Examples
    --------
    >>> header_comments("# one\\n#two\\nname: x  # not this\\n")
    ['# one', '#two']
    """
    out = []
    for line in text.splitlines():
        if line.startswith("#"):
            out.append(line)
        elif line.strip():
            break
    return out


def write_bank_text(path: os.PathLike, text: str) -> None:
    """Write bank.yaml text atomically (temporary file, fsync, rename).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "bank.yaml"
    >>> write_bank_text(p, "name: x"); p.read_text()
    'name: x'
    """
    atomic_write_bytes(Path(path), lambda fh: fh.write(text.encode("utf-8")))
