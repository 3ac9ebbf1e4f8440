"""Mouth samples: the real lower-face frames a bank made from video keeps, to be selected per frame.

A bank made by ``lipsync init --video`` keeps, beside its one picture per viseme, every
usable frame of its footage's lower face as a *sample*, at the footage's own scale: the
crop of the source frame (cut at integer offsets, so not resampled) and a row of a table
saying where it came from (clip, frame, run of consecutive frames), how the mouth looks
(opening, width, protrusion, the lip points), what was said (the phone and its
neighbours) and the affine taking the crop's pixels to the bank's canonical face frame.
:mod:`lipsync.selection` chooses one sample per rendered frame; the renderers paste it
with one warp.

* :mod:`.store` — the on-disk format (``samples.mp4`` + ``samples.npz`` beside
  bank.yaml), loading and validation;
* :mod:`.build` — making them from the footage (called by :func:`lipsync.videobank.make_bank`);
* :mod:`.quality` — how sharp each sample's lips are, and how much softer than usual for
  its opening (motion blur), which the selection charges.

Examples
--------
>>> from lipsync.samples import TABLE_NAME, VIDEO_NAME
>>> VIDEO_NAME, TABLE_NAME
('samples.mp4', 'samples.npz')
"""

from __future__ import annotations

from .store import TABLE_NAME, VIDEO_NAME, Samples, load_samples, read_table, samples_wanted

__all__ = ["Samples", "load_samples", "read_table", "samples_wanted", "VIDEO_NAME", "TABLE_NAME"]
