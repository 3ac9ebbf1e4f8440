"""Sprite atlases for game engines: morphed lip sync without lipsync at run time.

``lipsync atlas BANK -o mouth.png`` renders every viseme and N in-betweens of each
transition into one RGBA texture plus ``mouth.json`` (where each cell is, which pair and
alpha it holds: :mod:`.schema`); ``lipsync cues INPUT --format atlas --atlas mouth.json
--fps F -o frames.json`` gives the cell of every frame (:mod:`.frames`). An engine then
draws ``cells[frames[floor(t * fps)]]`` on its own clock. ``static/player.html`` is a
plain-JavaScript player of the three files and the speech, as an example for engines.

Modules: :mod:`.schema` (the JSON documents, light: the cue writer imports it),
:mod:`.frames` (frames to cells), :mod:`.layout` (packing), :mod:`.build` (rendering; imports
the renderer, so it is loaded only when used).
"""

from __future__ import annotations

from .frames import CellIndex, quantise
from .schema import SCHEMA_VERSION, Atlas, Cell, load_atlas

__all__ = ["Atlas", "Cell", "CellIndex", "SCHEMA_VERSION", "build_atlas", "load_atlas", "player_files",
           "quantise", "write_atlas"]


def __getattr__(name):
    # build_atlas / write_atlas pull in the renderer (OpenCV, the kernels): only on use.
    if name in ("build_atlas", "write_atlas", "AtlasBuild", "compose", "pairs_in_plan", "pairs_in_specs",
                "bank_pairs"):
        from . import build

        return getattr(build, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def player_files():
    """Paths of the example players, shipped with lipsync: the page (``player.html``,
    ``player.js``) and the Godot 3 script (``lipsync_player.gd``).

    Examples
    --------
    >>> sorted(p.name for p in player_files())
    ['lipsync_player.gd', 'player.html', 'player.js']
    """
    from pathlib import Path

    static = Path(__file__).with_name("static")
    return [static / "player.html", static / "player.js", static / "lipsync_player.gd"]
