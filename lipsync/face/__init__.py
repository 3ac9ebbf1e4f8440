"""Faces: landmarks, tracking through video, measures, and control lines from a face.

The room's parts, each depending only on those above it:

* :mod:`~lipsync.face.topology` — named point groups of the 468-point face mesh;
* :mod:`~lipsync.face.landmarks` — MediaPipe's face detector and face mesh (shipped in
  ``models/``, Apache 2.0) run with LiteRT, with the pre- and post-processing written out;
* :mod:`~lipsync.face.measure` — lip opening, mouth width, eye opening ... in eye distances;
* :mod:`~lipsync.face.video` — frames of any video ffmpeg reads;
* :mod:`~lipsync.face.track` — the face followed through a video, smoothed without lag;
* :mod:`~lipsync.face.lines` — the template that turns a mesh into a bank's control lines;
* :mod:`~lipsync.face.compare` — two pictures of a face registered by the still points, and
  the mouth region's PSNR and SSIM (what real-footage measurements use).

Examples
--------
>>> import numpy as np
>>> from lipsync.face import FaceMesh
>>> FaceMesh().detect(np.zeros((96, 96, 3), np.uint8))
[]
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "FaceMesh": "landmarks",
    "Detection": "landmarks",
    "Roi": "landmarks",
    "NoFaceError": "landmarks",
    "FaceWarning": "landmarks",
    "FaceTrack": "track",
    "Tracker": "track",
    "track_frames": "track",
    "track_video": "track",
    "probe_video": "video",
    "read_video": "video",
    "VideoInfo": "video",
    "face_features": "lines",
    "FACE_TEMPLATE": "lines",
    "lip_opening": "measure",
    "mouth_width": "measure",
    "eye_distance": "measure",
}


def __getattr__(name: str) -> Any:
    # Lazy: importing lipsync.face must not load LiteRT (or cv2) until a model is used.
    if name in _EXPORTS:
        return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    raise AttributeError(f"module 'lipsync.face' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_EXPORTS))
