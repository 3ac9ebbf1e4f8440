"""The Blender add-on lipsync ships: its source (``addon/lipsync_blender/``) and its zip.

The add-on runs on Blender's own Python without lipsync installed: it reads only the files
lipsync writes (PNG sequences, atlas + frames.json, mouth cues). ``lipsync blender-addon -o
lipsync_blender.zip`` writes the zip Blender installs (Edit > Preferences > Add-ons >
Install). The add-on folder has no ``__init__.py`` above it on purpose: it is package data,
never imported by lipsync (its modules import ``bpy``). docs/blender.md has the user's guide.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path
from typing import List, Union

__all__ = ["ADDON_MODULE", "addon_files", "write_addon_zip"]

#: The add-on's module name inside Blender (the folder in the zip).
ADDON_MODULE = "lipsync_blender"

# Zip entries get this fixed time, so the same add-on gives the same zip, byte for byte.
_ZIP_TIME = (2026, 1, 1, 0, 0, 0)


def addon_files() -> List[Path]:
    """The add-on's source files, shipped with lipsync, in a stable order.

    Examples
    --------
    >>> [p.name for p in addon_files()]
    ['__init__.py', 'build.py', 'files.py']
    """
    folder = Path(__file__).with_name("addon") / ADDON_MODULE
    return sorted(folder.glob("*.py"))


def write_addon_zip(path: Union[str, "os.PathLike[str]"]) -> Path:
    """Write the installable Blender add-on zip (``lipsync_blender/*.py``) to ``path``.

    Written under a temporary name and renamed into place; the same lipsync writes the
    same bytes.

    Parameters
    ----------
    path : str or path-like
        The zip to write (its folder is made if missing).

    Returns
    -------
    pathlib.Path

    Examples
    --------
    >>> import tempfile, zipfile, os
    >>> out = write_addon_zip(os.path.join(tempfile.mkdtemp(), "lipsync_blender.zip"))
    >>> sorted(zipfile.ZipFile(out).namelist())
    ['lipsync_blender/__init__.py', 'lipsync_blender/build.py', 'lipsync_blender/files.py']
    """
    from .._files import atomic_write_bytes

    out = Path(os.fspath(path))
    sources = addon_files()

    def write(fh):
        with zipfile.ZipFile(fh, "w", zipfile.ZIP_DEFLATED) as zf:
            for src in sources:
                info = zipfile.ZipInfo(f"{ADDON_MODULE}/{src.name}", date_time=_ZIP_TIME)
                info.external_attr = 0o644 << 16
                info.compress_type = zipfile.ZIP_DEFLATED
                zf.writestr(info, src.read_bytes())

    atomic_write_bytes(out, write)
    return out
