"""A new subject from video of the speaker: ``lipsync init OUTDIR --video VIDEO ...``.

The room sits beside :mod:`lipsync.banks` (banks from images) and builds on the rooms below
it: :mod:`lipsync.face` (landmarks, tracking, lines from a face), :mod:`lipsync.speech`
(alignment), :mod:`lipsync.morphing.preprocess` (flows). One module per step, each a function over a
typed value, run in order by :func:`make_bank`:

* :mod:`.sources` — the videos and their transcripts, checked before any long work;
* :mod:`.speech` — the speech aligned and mapped to visemes (when each shape is shown);
* :mod:`.stabilise` — every frame mapped onto one reference pose by the still points, and
  the crop around the head;
* :mod:`.select` — candidate frames per viseme and their ranking;
* :mod:`.cut` — the finalists cut out of the videos at the bank's size;
* :mod:`.colour` — exposure and white balance matched on the still skin;
* :mod:`.write` — PNGs, bank.yaml, the report, the preview sheet and the flows, all or
  nothing.

The options travel in one frozen :class:`~lipsync.videobank.config.VideoBankConfig`.

Examples
--------
>>> from lipsync.videobank import VideoBankConfig
>>> VideoBankConfig(force=True).force
True
"""

from __future__ import annotations

from .config import VideoBankConfig, parse_size
from .make import VideoBankResult, make_bank

__all__ = ["make_bank", "VideoBankConfig", "VideoBankResult", "parse_size"]
