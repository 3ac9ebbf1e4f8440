"""The embedding API: a timeline and a bank in, RGB frames out.

The whole pipeline in one place (DESIGN.md)::

    read_timeline -> map_timeline -> sequence -> Renderer.render per FrameSpec

Examples
--------
>>> from lipsync import Animator, Bank, Segment, Timeline
>>> from lipsync._data import default_bank_dir
>>> bank = Bank.load(default_bank_dir())
>>> tl = Timeline((Segment(0.0, 0.3, "M"), Segment(0.3, 0.7, "AA"), Segment(0.7, 1.0, "sil")),
...               kind="phoneme")
>>> anim = Animator(bank, tl, fps=25)
>>> len(anim), anim.frame_at(0.5).shape
(25, (512, 512, 3))
"""

from __future__ import annotations

import math
import os
import threading
from typing import Iterator, List, Optional, Union

import numpy as np

from ..banks.bank import Bank
from ..motion.coarticulation import resolve_timing, viseme_classes
from ..errors import InputError
from ..phonetics.phonemes import DEFAULT_MAP, PhonemeMap, bank_viseme_timeline, load_map
from ..readers import read_timeline
from ..morphing.render import Renderer
from ..motion.frames import DEFAULT_FPS
from ..motion.sequencer import FrameSpec, check_fps, sequence
from ..morphing.store import FlowStore
from ..motion.timeline import Timeline


class Animator:
    """Frames of a talking head for a timeline, by index, by time, or as a stream.

    Parameters
    ----------
    bank : Bank or path-like
        The subject (a loaded bank or its folder).
    timeline : Timeline or path-like
        A phoneme or viseme timeline, or a file any reader understands.
    fps : float
        Output frame rate, 1 to 120.
    map : str, path-like or PhonemeMap, optional
        Phoneme-to-viseme map (default: the shipped English to Rhubarb-shapes map).
    method : str
        Renderer method: ``flow`` (default), ``splat``, ``beier-neely`` or ``dissolve``.
    timing : str, callable or DominanceParams, optional
        How the mouth moves: a transition curve name (``lipsync.motion.timing.CURVES``), a callable
        curve, or ``"dominance"`` (coarticulation, :mod:`lipsync.motion.coarticulation`). Default:
        the bank's ``timing`` in bank.yaml, else the paper's text reading ``sqrt-fast-middle``
        (:func:`lipsync.motion.coarticulation.resolve_timing`).
    store : FlowStore, optional
        Flow store (default: the bank's). Missing flows are computed on first use.
    timeline_options : argparse.Namespace, optional
        Reader options (``timeline_format``, ``tier``, ``sample_rate``, ``moho_fps``, and
        ``text``, an audio file's transcript) used when ``timeline`` is a path.
    still : bool
        Show the bank's still pictures even when it has an idle plate (bank.yaml ``plate:``,
        banks made from video). By default frame i of such a bank is plate frame
        :meth:`lipsync.composite.plate.Plate.index` with the morphed lower face on it
        (:mod:`lipsync.composite.plate`): the speaker's own blinks and head motion.
    plate_start : float, optional
        Seconds into the idle plate where the clip starts (``--plate-start``); default: a
        place derived from the timeline (:func:`lipsync.composite.plate_time.default_start`).
    samples : {None, "on", "off"} or bool
        Whether a bank with mouth samples (bank.yaml ``samples:``, banks made from video)
        shows a real sample per frame on its plate (:mod:`lipsync.pipeline.samplepath`);
        None: as bank.yaml says; ``"off"``: one picture per viseme, morphed.
    audio : path-like or numpy.ndarray, optional
        The speech the timeline is of (a file, or 16 kHz mono samples): with samples, a bank
        with an audio lip model selects them for the lip movement the sound predicts
        (:mod:`lipsync.samples.lipmodel`); :meth:`from_audio` passes its audio.

    Attributes
    ----------
    specs : list of FrameSpec
        One per frame: ``(from_viseme, to_viseme, alpha)``.
    visemes : Timeline
        The mapped viseme timeline.
    plate : lipsync.composite.plate.Plate or None
        The idle plate frames are composited onto (None: the still pictures).
    sample_path : lipsync.pipeline.samplepath.SamplePath or None
        The selected samples (None: the viseme morph).
    """

    #: The selected mouth samples (None: the viseme morph; a subclass that skips
    #: :meth:`_attach_samples`, such as the live path's, keeps the morph).
    sample_path = None

    def __init__(self, bank: Union[Bank, str, "os.PathLike[str]"], timeline, fps: float = DEFAULT_FPS, *,
                 map: Union[str, "os.PathLike[str]", PhonemeMap, None] = None, method: str = "flow",
                 timing=None, store: Optional[FlowStore] = None, timeline_options=None, still: bool = False,
                 plate_start: Optional[float] = None, samples=None, audio=None):
        self.bank = bank if isinstance(bank, Bank) else Bank.load(bank)
        self.fps = check_fps(fps)
        if not isinstance(timeline, Timeline):
            o = timeline_options
            timeline = read_timeline(timeline, getattr(o, "timeline_format", None), tier=getattr(o, "tier", None),
                                     sample_rate=getattr(o, "sample_rate", 16000),
                                     fps=getattr(o, "moho_fps", 24.0), text=getattr(o, "text", None),
                                     quiet=getattr(o, "quiet", True), lang=getattr(o, "lang", None))
        pmap = map if isinstance(map, PhonemeMap) else load_map(map or DEFAULT_MAP)
        map_path = map if isinstance(map, (str, os.PathLike)) and os.path.isfile(map) else None
        self.visemes, pmap = bank_viseme_timeline(timeline, pmap, self.bank.names, rest=self.bank.rest,
                                                  map_path=map_path)
        self.timing = resolve_timing(timing, self.bank)
        self.specs: List[FrameSpec] = sequence(self.visemes, fps=self.fps, rest=self.bank.rest, timing=self.timing,
                                               closures=pmap.closures, classes=viseme_classes(pmap, self.bank.rest))
        self.renderer = Renderer(self.bank, method=method, store=store)
        self._attach_plate(still, plate_start)
        self._attach_samples(samples, timeline, pmap, store, audio)

    def _attach_samples(self, option, timeline, pmap, store, audio=None) -> None:
        """Select the bank's mouth samples when it has them, they are on and frames go onto its plate."""
        from .samplepath import SamplePath, bank_samples

        self.sample_path = None
        self.phones, self.pmap = timeline, pmap  # what a dub's own sample path selects for
        if self.plate is None or not self.specs:
            return
        samples = bank_samples(self.bank, option)
        if samples is not None:
            self.sample_path = SamplePath(samples, self.specs, timeline, self.fps, pmap, self.bank.rest,
                                          store=store or FlowStore.for_bank(self.bank), timing=self.timing,
                                          audio=audio)

    def _attach_plate(self, still: bool, plate_start: Optional[float] = None) -> None:
        """The bank's idle plate to composite onto, unless ``still`` (or the bank has none),
        and this clip's way through it (:mod:`lipsync.composite.plate_time`): from
        ``plate_start`` seconds, by default a place derived from the frames' mouth shapes (the
        same clip the same frames; another sentence another place)."""
        self.plate = None
        self.plate_line = None
        if not still and self.bank.plate is not None and self.bank.channels == 3:
            from ..composite.plate import load_plate
            from ..composite.plate_time import default_start

            self.plate = load_plate(self.bank)
            self._mouth = threading.local()  # each render thread its own morphed frame
            if self.plate is None:  # switched off in bank.yaml
                return
            if plate_start is None:  # the frames' own content (an Animator's or a LiveClip's specs)
                key = [(s.from_viseme, s.to_viseme, round(float(s.alpha), 4)) for s in self.specs]
                plate_start = default_start(key) * len(self.plate) / self.plate.fps
            #: Where on the plate this clip starts, seconds (``--plate-start``).
            self.plate_start = float(plate_start)
            self.plate_line = self.plate.timeline(self.plate_start)

    @classmethod
    def from_audio(cls, bank: Union[Bank, str, "os.PathLike[str]"], audio, text: Optional[str] = None,
                   fps: float = DEFAULT_FPS, *, lang: Optional[str] = None, **kwargs) -> "Animator":
        """An Animator for a speech recording: aligned with pocketsphinx, then as usual.

        Parameters
        ----------
        bank : Bank or path-like
            The subject.
        audio : path-like or numpy.ndarray
            Any audio file ffmpeg reads, or 16 kHz mono samples (int16, or floats in -1..1).
        text : str, optional
            The transcript, or a text file holding it; None: the words are recognised.
        fps : float
            Output frame rate.
        lang : str, optional
            The speech's language (BCP 47; default English): see :func:`lipsync.speech.align.align`.
        **kwargs
            ``map``, ``method``, ``timing``, ``store`` as for :class:`Animator`.

        Returns
        -------
        Animator
            With ``alignment`` (the :class:`lipsync.speech.align.Alignment`: words and phones).

        Examples
        --------
        >>> import os
        >>> from lipsync import Animator
        >>> from lipsync._data import default_bank_dir
        >>> wav = os.path.join(os.path.dirname(default_bank_dir()), "..", "samples", "hello.wav")
        >>> anim = Animator.from_audio(default_bank_dir(), wav, "Hello, I am a talking head made by lipsync.")
        >>> len(anim), anim.alignment.words.labels()[:4]
        (75, ['hello', 'i', 'am', 'a'])
        """
        import warnings

        from ..speech.align import MissingWordsWarning, align

        with warnings.catch_warnings():
            # "lipsync" is not in CMUdict; the caller can read alignment.missing instead.
            warnings.simplefilter("ignore", MissingWordsWarning)
            alignment = align(audio, text, lang=lang)
        kwargs.setdefault("audio", audio)
        anim = cls(bank, alignment.phones, fps=fps, **kwargs)
        anim.alignment = alignment
        return anim

    def __len__(self) -> int:
        return len(self.specs)

    @property
    def duration(self) -> float:
        """Seconds covered by the frames (``len(self) / fps``)."""
        return len(self.specs) / self.fps

    def frame(self, index: int, *, out: Optional[np.ndarray] = None) -> np.ndarray:
        """Frame ``index`` (it shows time ``index / fps``), a new array unless ``out`` is given."""
        if not 0 <= index < len(self.specs):
            raise IndexError(f"frame {index} out of range 0..{len(self.specs) - 1}")
        spec = self.specs[index]
        if out is None:
            out = np.empty(self.renderer.shape + (self.renderer.channels,), np.uint8)
        if self.plate is None:
            return self.renderer.render(spec.from_viseme, spec.to_viseme, spec.alpha, out=out)
        mouth = getattr(self._mouth, "frame", None)
        if mouth is None:
            mouth = self._mouth.frame = np.empty_like(out)
        if self.sample_path is not None:
            j = self.plate.index(index, self.fps, self.plate_line)
            np.copyto(out, self.plate.frames[j])
            pose = self.plate.poses[j]
            return self.sample_path.render_onto(index, out, pose, self.sample_path.prepared(j, pose, out.shape))
        # only the lower face's box of the morph is read: only that box is rendered
        self.renderer.render(spec.from_viseme, spec.to_viseme, spec.alpha, out=mouth, region=self.plate.region)
        return self.plate.render_into(index, self.fps, mouth, out, self.plate_line)

    def same_as_previous(self, index: int) -> bool:
        """Whether frame ``index`` is identical to frame ``index - 1`` (a held shape).

        Frames are a pure function of (from, to, alpha), and alpha 0 or 1 (or from = to)
        is simply that viseme's image, so equal specs mean equal frames.

        Examples
        --------
        >>> from lipsync._data import default_bank_dir
        >>> from lipsync.motion.timeline import Segment, Timeline
        >>> a = Animator(default_bank_dir(), Timeline((Segment(0.0, 0.4, "sil"),), kind="phoneme"), fps=25)
        >>> a.same_as_previous(0), a.same_as_previous(5)
        (False, True)
        """
        if not 0 < index < len(self.specs) or self.plate is not None:  # a plate moves in every frame
            return False
        return _still_key(self.specs[index]) == _still_key(self.specs[index - 1])

    def frame_at(self, t: float) -> np.ndarray:
        """The frame shown at time ``t`` seconds (the frame whose interval holds ``t``).

        Total for every number: a time before 0 gives the first frame, one past the end
        (however large, infinity included) the last, and a timeline with no frames the rest
        viseme. A NaN time is refused (InputError, a ValueError): it is a bug in the
        caller's clock, and any frame shown for it would hide that.

        Examples
        --------
        >>> from lipsync._data import default_bank_dir
        >>> from lipsync.motion.timeline import Segment, Timeline
        >>> a = Animator(default_bank_dir(), Timeline((Segment(0.0, 0.4, "AA"),), kind="phoneme"), fps=25)
        >>> bool((a.frame_at(1e308) == a.frame(len(a) - 1)).all()), a.frame_at(-5.0).shape
        (True, (512, 512, 3))
        """
        t = float(t)
        if math.isnan(t):
            raise InputError("time must be a number, got nan")
        if not self.specs:
            return self.renderer.render(self.bank.rest, self.bank.rest, 0.0)
        pos = t * self.fps  # inf for huge t: compared as a float, never made an int
        index = 0 if pos <= 0 else len(self.specs) - 1 if pos >= len(self.specs) else int(math.floor(pos + 1e-9))
        return self.frame(min(index, len(self.specs) - 1))

    def frames(self, *, copy: bool = True) -> Iterator[np.ndarray]:
        """Every frame in order.

        With ``copy=False`` each yielded array is the renderer's buffer, valid until the
        next frame is requested: the fast path for streaming to an encoder.
        """
        if self.plate is not None:
            buf = np.empty(self.renderer.shape + (self.renderer.channels,), np.uint8)
            for i in range(len(self.specs)):
                frame = self.frame(i, out=buf)
                yield frame.copy() if copy else frame
            return
        for spec in self.specs:
            frame = self.renderer.render(spec.from_viseme, spec.to_viseme, spec.alpha)
            yield frame.copy() if copy else frame


def _still_key(spec) -> tuple:
    """What a frame shows: one viseme's image, or (from, to, alpha) strictly in between."""
    if spec.from_viseme == spec.to_viseme or spec.alpha <= 0.0:
        return (spec.from_viseme,)
    if spec.alpha >= 1.0:
        return (spec.to_viseme,)
    return (spec.from_viseme, spec.to_viseme, spec.alpha)
