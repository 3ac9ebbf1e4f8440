"""Timing curves: monotone, f(0)=0, f(1)=1, vectorised, and the paper's two readings."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lipsync.errors import UnknownNameError
from lipsync.motion.timing import CURVES, DEFAULT_CURVE, get_curve

T = np.linspace(0.0, 1.0, 2001)


@pytest.mark.parametrize("name", CURVES.names())
def test_every_curve_monotone_with_fixed_ends(name):
    f = get_curve(name)
    y = np.asarray(f(T))
    assert y.shape == T.shape
    assert f(0.0) == 0.0 and f(1.0) == 1.0
    assert np.all(np.diff(y) >= -1e-12)
    assert y.min() >= 0.0 and y.max() <= 1.0
    # Scalars in, Python floats out; arrays agree with scalar calls.
    assert isinstance(f(0.3), float)
    assert [f(float(t)) for t in T[::97]] == pytest.approx(list(y[::97]))


def _paper_text(t):
    return 0.5 - 0.5 * math.sqrt(1 - 2 * t) if t < 0.5 else 0.5 + 0.5 * math.sqrt(2 * t - 1)


def _paper_caption(t):
    return 0.5 * math.sqrt(2 * t) if t < 0.5 else 1 - 0.5 * math.sqrt(2 - 2 * t)


def test_piecewise_sqrt_curves_match_the_formulas():
    fm, fe = get_curve("sqrt-fast-middle"), get_curve("sqrt-fast-ends")
    for t in (0.0, 0.02, 0.1, 0.25, 0.4999, 0.5, 0.5001, 0.75, 0.9, 0.98, 1.0):
        assert fm(t) == pytest.approx(_paper_text(t), abs=1e-12)
        assert fe(t) == pytest.approx(_paper_caption(t), abs=1e-12)
    # Vectorised evaluation agrees with the scalar formulas.
    assert np.asarray(fm(T)) == pytest.approx([_paper_text(t) for t in T], abs=1e-12)
    assert np.asarray(fe(T)) == pytest.approx([_paper_caption(t) for t in T], abs=1e-12)


def test_fast_middle_is_slow_at_the_ends_and_fast_ends_the_opposite():
    fm, fe = get_curve("sqrt-fast-middle"), get_curve("sqrt-fast-ends")
    h = 0.01
    slope = lambda f, t: (f(t + h) - f(t)) / h  # noqa: E731
    # Analytic slopes: fast-middle has f' = 1/2 at the ends and is unbounded at t = 1/2;
    # fast-ends is unbounded at the ends and has f' = 1/2 at t = 1/2.
    assert slope(fm, 0.0) < 0.6 and slope(fm, 1.0 - h) < 0.6 and slope(fm, 0.5 - h / 2) > 5
    assert slope(fe, 0.0) > 5 and slope(fe, 1.0 - h) > 5 and slope(fe, 0.5 - h / 2) < 0.6


def test_smoothstep_and_linear_values():
    assert get_curve("smoothstep")(0.25) == pytest.approx(3 * 0.0625 - 2 * 0.015625)
    assert get_curve("linear")(0.37) == pytest.approx(0.37)


def test_default_is_the_papers_text_reading():
    assert DEFAULT_CURVE == "sqrt-fast-middle" and DEFAULT_CURVE in CURVES.names()


def test_callables_are_accepted_and_vectorised():
    scalar_only = lambda t: min(1.0, max(0.0, t)) ** 3  # noqa: E731  # breaks on arrays (min of an array)
    f = get_curve(scalar_only)
    assert np.asarray(f(np.array([0.0, 0.5, 1.0]))) == pytest.approx([0.0, 0.125, 1.0])
    assert f(0.5) == pytest.approx(0.125)
    g = get_curve(lambda t: 2 * t)  # out of range results are clipped to [0, 1]
    assert g(0.75) == 1.0


def test_unknown_curve_names_the_valid_ones():
    with pytest.raises(UnknownNameError) as info:
        get_curve("bouncy")
    assert all(n in str(info.value) for n in CURVES.names())
