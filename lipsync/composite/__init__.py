"""Compositing room: where rendered mouth frames go, and how a lower face joins a plate.

* :mod:`lipsync.composite.sprites` -- a drawn mouth onto a character's body, a background,
  or as it is (bank.yaml ``composite:``, ``lipsync render --over``).
* :mod:`lipsync.composite.face` -- one face: a lower face (mouth, jaw, chin) pasted onto a
  plate picture (the lower-face mask, the pose and colour match, the blend).
* :mod:`lipsync.composite.plate` -- the morphed lower face onto frames of real video, per
  frame and ROI-only: a bank's idle plate (``lipsync render``) and the video being re-voiced
  (``lipsync dub``, :mod:`lipsync.pipeline.dubbing`).
* :mod:`lipsync.composite.plate_time` -- which plate frame each output frame shows: where a
  clip starts (``--plate-start``), and a plate shorter than the output joined to itself
  where its frames match, never mid-blink (Video Textures), instead of ping-pong.

The names below are the ones ``lipsync.composite`` has always had.
"""

from .sprites import (DEFAULT_BACKGROUND, MAX_SCALE, Composite, Compositor, check_placement,
                      parse_at)

__all__ = ["Composite", "Compositor", "DEFAULT_BACKGROUND", "MAX_SCALE", "parse_at", "check_placement"]
