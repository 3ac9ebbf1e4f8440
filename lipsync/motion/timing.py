"""Timing curves: how the morph parameter alpha advances during a transition.

A curve maps the elapsed fraction ``t`` of a transition (0..1) to alpha (0..1); every
registered curve is monotone with f(0) = 0 and f(1) = 1, and works on numpy arrays.

The paper (section 4 and fig. 6) uses a piecewise square-root curve but its text and its
figure caption disagree about which way round (erratum 2 in DESIGN.md):

``sqrt-fast-middle``  (the paper's *text*)
    f(t) = 0.5 - 0.5*sqrt(1 - 2t) for t < 0.5, 0.5 + 0.5*sqrt(2t - 1) after.
    Slope 1/2 at both ends and unbounded at t = 0.5: the mouth eases out of one shape,
    moves quickly through the in-between, and settles gently into the next.
``sqrt-fast-ends``  (the paper's *fig. 6 caption*)
    f(t) = 0.5*sqrt(2t) for t < 0.5, 1 - 0.5*sqrt(2 - 2t) after.
    Unbounded slope at both ends, slope 1/2 in the middle: it jumps away from a shape,
    lingers on the half-way blend, then snaps onto the target.

**Default: sqrt-fast-middle.** Real articulators accelerate and decelerate (they have mass),
which is what the text describes and what animators' "slow in, slow out" does; it also keeps
most frames near a real viseme and few on the half-way blend, which is the frame most
prone to double-image ghosting. The caption's reading does the opposite on both counts.

Examples
--------
>>> f = get_curve("sqrt-fast-middle")
>>> float(f(0.0)), float(f(0.5)), float(f(1.0))
(0.0, 0.5, 1.0)
>>> round(float(get_curve("sqrt-fast-ends")(0.125)), 3)
0.25
"""

from __future__ import annotations

from typing import Callable, List, Union

import numpy as np

from ..errors import InputError, UnknownNameError
from ..registry import Registry

ArrayLike = Union[float, np.ndarray]
Curve = Callable[[ArrayLike], ArrayLike]

CURVES: Registry[Curve] = Registry("timing curve")


def _clip(t: ArrayLike) -> np.ndarray:
    return np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)


def _out(t: ArrayLike, value: np.ndarray) -> ArrayLike:
    return float(value) if np.ndim(t) == 0 else value


def linear(t: ArrayLike) -> ArrayLike:
    """alpha = t: constant speed (a plain cross-fade schedule)."""
    x = _clip(t)
    return _out(t, x)


def sqrt_fast_middle(t: ArrayLike) -> ArrayLike:
    """The paper's text: slow at both ends, fastest through the middle."""
    x = _clip(t)
    low = 0.5 - 0.5 * np.sqrt(np.maximum(1.0 - 2.0 * x, 0.0))
    high = 0.5 + 0.5 * np.sqrt(np.maximum(2.0 * x - 1.0, 0.0))
    return _out(t, np.where(x < 0.5, low, high))


def sqrt_fast_ends(t: ArrayLike) -> ArrayLike:
    """The paper's fig. 6 caption: fast at both ends, slowest in the middle."""
    x = _clip(t)
    low = 0.5 * np.sqrt(np.maximum(2.0 * x, 0.0))
    high = 1.0 - 0.5 * np.sqrt(np.maximum(2.0 - 2.0 * x, 0.0))
    return _out(t, np.where(x < 0.5, low, high))


def smoothstep(t: ArrayLike) -> ArrayLike:
    """3t² − 2t³: zero slope at both ends, slope 3/2 in the middle (a bounded ease-in-out)."""
    x = _clip(t)
    return _out(t, x * x * (3.0 - 2.0 * x))


CURVES.register("linear", linear)
CURVES.register("sqrt-fast-middle", sqrt_fast_middle, aliases=("paper-text", "ease-in-out-sqrt"))
CURVES.register("sqrt-fast-ends", sqrt_fast_ends, aliases=("paper-figure", "ease-out-in-sqrt"))
CURVES.register("smoothstep", smoothstep)

DEFAULT_CURVE = "sqrt-fast-middle"

#: Timing models that are not a transition curve of the rule-based sequencer: each replaces
#: the sequencer's transitions altogether (name -> what it is). ``dominance`` is the
#: coarticulation model of :mod:`lipsync.motion.coarticulation`: every sound pulls the mouth toward
#: its shape with a dominance that rises before it and decays after it (Cohen & Massaro).
#: Wherever a timing is chosen (``--timing``, ``timing=``, bank.yaml's ``timing:``, a batch
#: manifest) a curve name and a model name are equally valid: see :func:`timing_names`.
MODELS: Registry[str] = Registry("timing model")
MODELS.register("dominance", "coarticulation: dominance functions fitted to real speech",
                aliases=("coarticulation",))


def timing_names() -> List[str]:
    """Every valid timing name: the curves, then the models (the CLI's ``--timing`` choices).

    Examples
    --------
    >>> timing_names()
    ['linear', 'sqrt-fast-middle', 'sqrt-fast-ends', 'smoothstep', 'dominance']
    """
    return CURVES.names() + MODELS.names()


def is_model(timing) -> bool:
    """True when ``timing`` names a timing model (not a curve).

    Examples
    --------
    >>> is_model("dominance"), is_model("Coarticulation"), is_model("linear"), is_model(lambda t: t)
    (True, True, False, False)
    """
    return isinstance(timing, str) and timing in MODELS


def check_timing(name: str) -> str:
    """A timing name as registered (curve or model); unknown names list every valid one.

    Examples
    --------
    >>> check_timing("paper-text"), check_timing("DOMINANCE")
    ('sqrt-fast-middle', 'dominance')
    """
    for registry in (CURVES, MODELS):
        if isinstance(name, str) and name in registry:
            return registry.canonical(name)
    raise UnknownNameError(f"unknown timing {name!r}; valid: {', '.join(timing_names())}")


def get_curve(name_or_callable: Union[str, Curve]) -> Curve:
    """A timing curve by registered name, or a callable passed through (vectorised).

    A user callable is wrapped so that it accepts numpy arrays even if it only handles
    scalars, and its result is clipped to [0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> get_curve("smoothstep")(np.array([0.0, 0.5, 1.0])).tolist()
    [0.0, 0.5, 1.0]
    >>> get_curve(lambda t: t * t)(np.array([0.5])).tolist()
    [0.25]
    """
    if isinstance(name_or_callable, str):
        if name_or_callable not in CURVES and name_or_callable in MODELS:
            raise InputError(f"{name_or_callable!r} is a timing model, not a transition curve "
                             f"(lipsync.motion.sequencer.sequence takes either)")
        return CURVES.get(name_or_callable)
    if not callable(name_or_callable):
        raise InputError(f"a timing curve must be a name or a callable, not {name_or_callable!r}")
    func = name_or_callable
    if func in (linear, sqrt_fast_middle, sqrt_fast_ends, smoothstep):
        return func

    def wrapped(t: ArrayLike) -> ArrayLike:
        x = _clip(t)
        try:
            y = np.asarray(func(x), dtype=np.float64)
            if y.shape != x.shape:
                raise ValueError
        except (TypeError, ValueError):
            y = np.vectorize(lambda v: float(func(float(v))), otypes=[np.float64])(x)
        return _out(t, np.clip(y, 0.0, 1.0))

    return wrapped
