"""The options of one ``lipsync init --video`` run, frozen and passed to every step.

Examples
--------
>>> VideoBankConfig().map
'english-to-rhubarb'
>>> VideoBankConfig(size=(320, 240)).size
(320, 240)
>>> parse_size("320x240")
(320, 240)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

from ..errors import InputError
from ..phonetics.phonemes import DEFAULT_MAP

#: Without ``--size`` the bank keeps the video's own scale (no detail invented, none lost),
#: but its longer side is held to this: the flows' cost and the renderer's grow with the
#: pixels (a 512x512 frame renders at several hundred frames/s on one core), and a phone's
#: 1080p close-up would otherwise make a 1500-pixel bank that renders no better on a
#: 512-pixel player. The shipped toon is 512x512 for the same reason.
DEFAULT_MAX_SIDE = 512
#: Sizes outside this range are a typo, not a bank (the flows of a 4096-pixel bank would
#: take minutes a pair).
SIZE_RANGE = (32, 2048)


@dataclass(frozen=True)
class VideoBankConfig:
    """Options of :func:`lipsync.videobank.make_bank`.

    Attributes
    ----------
    map : str
        Phoneme-to-viseme map (a shipped name or a YAML path): the bank gets one image per
        viseme it can produce.
    size : (int, int), optional
        ``(W, H)`` of the bank's images; default: the video's scale, longer side at most
        ``max_side``.
    max_side : int
        See :data:`DEFAULT_MAX_SIDE`.
    force : bool
        Replace a non-empty output folder.
    quiet : bool
        No progress bars.
    jobs : int, optional
        Processes for the flows (default: all cores).
    lang : str, optional
        Language of the speech and transcripts (BCP 47; default English): see
        :func:`lipsync.speech.align.align`.
    flows : bool
        Compute the flows (a bank ready to render); off only for tests of the other steps.
    one_face : bool
        Every viseme's picture is the rest picture (the *plate*, eyes open) outside the
        lower face, with the chosen frame's mouth, jaw and chin pasted in
        (:mod:`lipsync.composite.face`); off: each picture is its own whole frame.
    span : bool
        Pictures span the speaker's range: an open shape's picture is chosen near its
        candidates' median lip opening moved further from the rest's
        (:data:`lipsync.videobank.select.SPAN_GAIN`); off: near the median (closures are the
        closed ones either way).
    samples : bool
        Keep every usable lower-face frame as a mouth sample (:mod:`lipsync.samples`; needs
        ``one_face``): renders select real frames and join them with flows.
    """

    map: str = DEFAULT_MAP
    size: Optional[Tuple[int, int]] = None
    max_side: int = DEFAULT_MAX_SIDE
    force: bool = False
    quiet: bool = True
    jobs: Optional[int] = None
    flows: bool = True
    one_face: bool = True
    span: bool = True
    samples: bool = True
    lang: Optional[str] = None

    def __post_init__(self):
        if self.size is not None:
            w, h = self.size
            lo, hi = SIZE_RANGE
            if not (lo <= w <= hi and lo <= h <= hi):
                raise InputError(f"--size {w}x{h}: width and height must be {lo}-{hi} pixels")
        if not SIZE_RANGE[0] <= self.max_side <= SIZE_RANGE[1]:
            raise InputError(f"max_side {self.max_side}: must be {SIZE_RANGE[0]}-{SIZE_RANGE[1]} pixels")


def parse_size(text: str) -> Tuple[int, int]:
    """``WxH`` → ``(W, H)``.

    Examples
    --------
    >>> parse_size("640X480")
    (640, 480)
    >>> parse_size("640")
    Traceback (most recent call last):
    ...
    lipsync.errors.InputError: --size: expected WxH in pixels (e.g. 320x240), got '640'
    """
    parts = text.lower().replace(" ", "").split("x")
    try:
        w, h = (int(p) for p in parts)
    except ValueError:
        raise InputError(f"--size: expected WxH in pixels (e.g. 320x240), got {text!r}") from None
    VideoBankConfig(size=(w, h))  # checks the range
    return w, h
