"""lipsync: phoneme timelines to talking-head video by morphing between viseme images.

The pipeline, one module per stage (see README.md)::

    Bank.load -> normalise -> flows (FlowStore) ;  read_timeline -> map_timeline -> sequence
    -> Renderer -> encode

Examples
--------
>>> import lipsync
>>> sorted(lipsync.timing.CURVES.names())
['linear', 'smoothstep', 'sqrt-fast-ends', 'sqrt-fast-middle']
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

# Public names and the module that defines each; imported on first use so that
# `import lipsync` stays cheap (the CLI's --help should not pay for cv2 and pydantic).
_EXPORTS = {
    "Bank": "bank",
    "BankError": "errors",
    "InputError": "errors",
    "TimelineError": "errors",
    "MapError": "errors",
    "Segment": "timeline",
    "Timeline": "timeline",
    "read_timeline": "readers",
    "PhonemeMap": "phonemes",
    "load_map": "phonemes",
    "map_timeline": "phonemes",
    "FrameSpec": "sequencer",
    "sequence": "sequencer",
    "FlowStore": "store",
    "Renderer": "render",
    "morph": "render",
    "Animator": "animator",
    "LiveAnimator": "live",
    "render_clip": "clip",
    "write_video": "clip",
    "dub": "dubbing",
}
_SUBMODULES = {"warp", "bank", "normalise", "flows", "store", "render", "timeline", "phonemes",
               "sequencer", "timing", "coarticulation", "encode", "animator", "registry", "errors", "cli", "preview", "clip", "live",
               "phonetics"}


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        module = importlib.import_module(f".{_EXPORTS[name]}", __name__)
        return getattr(module, name)
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'lipsync' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_EXPORTS) + list(_SUBMODULES))
