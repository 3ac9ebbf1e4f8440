"""lipsync: phoneme timelines to talking-head video by morphing between viseme images.

The pipeline, one room (folder) per stage, each importing only rooms below it
(tests/test_layers.py)::

    motion/      timeline, timing curves, frames, coarticulation, sequencer  (visemes -> frame specs)
    phonetics/   IPA segments and features, phoneme maps, letters-to-sounds   (phones -> visemes)
    speech/      audio, transcripts, alignment, recognition                  (audio -> phones)
    readers/     timeline formats in
    banks/       Bank (bank.yaml and pictures), writing bank.yaml             (load)
    morphing/    warp, normalise, flows, refine, store, preprocess, render, alpha, kernels
    face/        landmarks, tracking, lines from a face
    composite/   sprites on a body, the lower face onto a plate
    encode/      yuv, ffmpeg, one module per output format, preview sheets
    live/        the causal animator, audio in
    videobank/   subjects from video and photos (lipsync init)
    pipeline/    Animator, render_clip, dub: the whole chain in one call
    atlas/ writers/ editor/ server/ batch/ cli/ bench/ web/ blender/   entry points

The modules that moved into rooms keep their old names as aliases (``lipsync.warp`` is
``lipsync.morphing.warp``); errors, the registry and private helpers stay at the top.

Examples
--------
>>> import lipsync
>>> sorted(lipsync.timing.CURVES.names())
['linear', 'smoothstep', 'sqrt-fast-ends', 'sqrt-fast-middle']
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
from typing import Any

__version__ = "0.1.0"

# Public names and the module that defines each; imported on first use so that
# `import lipsync` stays cheap (the CLI's --help should not pay for cv2 and pydantic).
_EXPORTS = {
    "Bank": "banks.bank",
    "BankError": "errors",
    "InputError": "errors",
    "TimelineError": "errors",
    "MapError": "errors",
    "Segment": "motion.timeline",
    "Timeline": "motion.timeline",
    "read_timeline": "readers",
    "PhonemeMap": "phonetics.phonemes",
    "load_map": "phonetics.phonemes",
    "map_timeline": "phonetics.phonemes",
    "FrameSpec": "motion.sequencer",
    "sequence": "motion.sequencer",
    "FlowStore": "morphing.store",
    "Renderer": "morphing.render",
    "morph": "morphing.render",
    "Animator": "pipeline.animator",
    "LiveAnimator": "live",
    "render_clip": "pipeline.clip",
    "write_video": "pipeline.clip",
    "dub": "pipeline.dubbing",
}
_SUBMODULES = {"warp", "bank", "normalise", "flows", "store", "render", "timeline", "phonemes",
               "sequencer", "timing", "coarticulation", "encode", "animator", "registry", "errors", "cli", "preview", "clip", "live",
               "phonetics"}


# Modules that moved into rooms (round four's layout). Their old dotted names stay importable
# (``import lipsync.warp``, ``from lipsync.bank import Bank``, pickles and user scripts):
# each old name is the same module object as the new one, not a copy.
_MOVED = {'warp': 'morphing.warp', 'normalise': 'morphing.normalise', 'flows': 'morphing.flows', 'refine': 'morphing.refine', 'store': 'morphing.store', 'preprocess': 'morphing.preprocess', 'render': 'morphing.render', '_numba_kernels': 'morphing._numba_kernels', 'alpha': 'morphing.alpha', '_flowkernel': 'morphing._flowkernel', 'yuv': 'encode.yuv', 'timeline': 'motion.timeline', 'timing': 'motion.timing', 'frames': 'motion.frames', 'coarticulation': 'motion.coarticulation', 'sequencer': 'motion.sequencer', 'bank': 'banks.bank', 'banks.init': 'videobank.photos', 'preview': 'encode.preview', 'phonemes': 'phonetics.phonemes', 'animator': 'pipeline.animator', 'clip': 'pipeline.clip', 'dubbing': 'pipeline.dubbing', 'live.offline': 'pipeline.liveclip'}


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Import ``lipsync.<old>`` as the module now at ``lipsync.<room>.<old>``."""

    def find_spec(self, fullname, path, target=None):
        if fullname.startswith(__name__ + ".") and fullname[len(__name__) + 1:] in _MOVED:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        module = importlib.import_module(f"{__name__}.{_MOVED[spec.name[len(__name__) + 1:]]}")
        spec.loader_state = module.__spec__
        return module

    def exec_module(self, module):
        # the import system has just set the alias's spec on the module: put its own back
        own = module.__spec__.loader_state
        module.__spec__, module.__loader__ = own, own.loader


sys.meta_path.insert(0, _MovedModules())


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        module = importlib.import_module(f".{_EXPORTS[name]}", __name__)
        return getattr(module, name)
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'lipsync' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_EXPORTS) + list(_SUBMODULES))
