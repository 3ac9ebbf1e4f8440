"""Normalisation to mirror-symmetric control lines (paper section 3 and 3.2).

Faces are close to symmetric but never exactly. When a bank asks for ``symmetry: true``,
every viseme's lines are replaced by the nearest exactly symmetric set (each line averaged
with its mirror partner's reflection) and the image is warped onto those lines with
bilinear resampling. Flows between symmetric line sets are mirror-symmetric, so only half
of each field has to be computed (see :mod:`lipsync.morphing.flows`).

The mirror axis is vertical, ``x = axis``. It is the median over visemes of each viseme's
own axis estimate, rounded to half a pixel: half-pixel positions map pixel centres onto
pixel centres (so mirroring a field is an exact column flip), and the median means that
editing one viseme rarely moves the axis, so the flow store keeps the other pairs.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Dict, Optional, Sequence, Tuple

import numpy as np

from ..banks.bank import Bank, mirror_partner_index
from .warp import beier_neely_map, warp


def mirror_points(points: np.ndarray, axis: float) -> np.ndarray:
    """Reflect points ``(..., 2)`` about the vertical line ``x = axis``.

    Examples
    --------
    >>> mirror_points(np.array([[10.0, 5.0]]), axis=20.0).tolist()
    [[30.0, 5.0]]
    """
    out = np.array(points, dtype=np.float64, copy=True)
    out[..., 0] = 2.0 * axis - out[..., 0]
    return out


def _partner_index(line_names: Sequence[str]) -> np.ndarray:
    # Curves (segments "name#i") pair up in bank.mirror_partner_index.
    return mirror_partner_index(line_names)


def estimate_axis(lines: np.ndarray, line_names: Sequence[str]) -> Optional[float]:
    """One viseme's mirror axis: the mean x of corresponding endpoints of mirror pairs.

    Lines without a partner lie on the axis or cross it symmetrically, so they contribute
    their own midpoint's x. Returns None when there are no lines.

    Examples
    --------
    >>> lines = np.array([[[10, 0], [20, 5]], [[50, 0], [40, 5]]], float)
    >>> estimate_axis(lines, ["lip_l", "lip_r"])
    30.0
    """
    if len(line_names) == 0:
        return None
    partners = _partner_index(line_names)
    mids = (lines[:, :, 0] + lines[partners, :, 0]) / 2.0
    return float(mids.mean())


def bank_axis(bank: Bank) -> float:
    """The shared mirror axis of a bank, rounded to half a pixel (see module docstring)."""
    estimates = [estimate_axis(bank.lines[v], bank.line_names) for v in bank.names]
    return float(np.round(2.0 * np.median(estimates)) / 2.0)


def symmetric_lines(lines: np.ndarray, line_names: Sequence[str], axis: float) -> np.ndarray:
    """The exactly mirror-symmetric line set nearest to ``lines``.

    A mirror pair (``x_l``, ``x_r``) becomes the average of ``x_l`` and the reflection of
    ``x_r`` (and its reflection); a line without partner is averaged with its own
    reflection, reversed if that reflection runs the other way (a horizontal line across
    the axis). The Beier–Neely warp does not depend on a line's direction, so reversal
    is harmless.

    Examples
    --------
    >>> lines = np.array([[[10, 0], [20, 4]], [[49, 2], [40, 6]]], float)
    >>> symmetric_lines(lines, ["lip_l", "lip_r"], axis=30.0).tolist()
    [[[10.5, 1.0], [20.0, 5.0]], [[49.5, 1.0], [40.0, 5.0]]]
    """
    lines = np.asarray(lines, dtype=np.float64)
    partners = _partner_index(line_names)
    reflected = mirror_points(lines[partners], axis)
    for i, j in enumerate(partners):
        # Unpaired lines, and segment i of an unpaired curve (whose mirror is segment N-1-i),
        # reflect onto themselves running backwards.
        if i == j or "#" in line_names[i] and line_names[i].partition("#")[0] == line_names[j].partition("#")[0]:
            same = np.abs(reflected[i] - lines[i]).sum()
            swapped = np.abs(reflected[i][::-1] - lines[i]).sum()
            if swapped < same:
                reflected[i] = reflected[i][::-1].copy()
    return (lines + reflected) / 2.0


def is_symmetric(lines: np.ndarray, line_names: Sequence[str], axis: float, tol: float = 1e-6) -> bool:
    """Whether ``lines`` equal their symmetric version within ``tol`` pixels."""
    return bool(np.abs(symmetric_lines(lines, line_names, axis) - lines).max() <= tol)


@dataclass(frozen=True)
class NormalisedBank:
    """A bank whose images and lines are what flows are computed from.

    Attributes
    ----------
    bank : Bank
        The bank as loaded (original images and lines).
    images, lines : dict
        Per viseme, the normalised image (RGB, or straight RGBA for a bank with
        transparency) and float64 ``(L, 2, 2)`` lines.
    axis : float or None
        The mirror axis when ``bank.symmetry``; None otherwise.
    """

    bank: Bank
    images: Dict[str, np.ndarray]
    lines: Dict[str, np.ndarray]
    axis: Optional[float]

    @property
    def names(self) -> Tuple[str, ...]:
        return self.bank.names

    @property
    def shape(self) -> Tuple[int, int]:
        return self.bank.shape


def normalise(bank: Bank, *, interpolation: str = "linear", cache=None) -> NormalisedBank:
    """Warp every viseme onto its symmetric line set (identity when ``symmetry`` is off).

    Parameters
    ----------
    bank : Bank
        A loaded bank.
    interpolation : {"linear", "nearest"}
        Resampling; bilinear avoids the staircasing of paper section 3.2.
    cache : FlowStore, optional
        When given, normalised images are stored and reused (one warp per viseme saved).

    Returns
    -------
    NormalisedBank

    Examples
    --------
    >>> from lipsync.banks.bank import Bank
    >>> from lipsync._data import default_bank_dir
    >>> nb = normalise(Bank.load(default_bank_dir()))
    >>> nb.axis is not None
    True
    """
    if not bank.symmetry:
        return NormalisedBank(bank=bank, images=dict(bank.images), lines=dict(bank.lines), axis=None)
    axis = bank_axis(bank)
    images: Dict[str, np.ndarray] = {}
    lines: Dict[str, np.ndarray] = {}
    for v in bank.names:
        sym = symmetric_lines(bank.lines[v], bank.line_names, axis)
        lines[v] = sym
        if np.abs(sym - bank.lines[v]).max() <= 1e-9:
            images[v] = bank.images[v]  # already symmetric: the warp is the identity
            continue
        cached = cache.get_normalised(bank, v, axis) if cache is not None else None
        if cached is None:
            cached = normalise_image(bank.images[v], bank.lines[v], sym, bank.warp.a, bank.warp.b,
                                     bank.warp.p, interpolation=interpolation)
            if cache is not None:
                cache.put_normalised(bank, v, axis, cached)
        images[v] = cached
    return NormalisedBank(bank=bank, images=images, lines=lines, axis=axis)


def normalise_image(image: np.ndarray, lines: np.ndarray, target_lines: np.ndarray, a: float = 1.0,
                    b: float = 2.0, p: float = 0.5, *, interpolation: str = "linear") -> np.ndarray:
    """Warp ``image`` so that its ``lines`` move to ``target_lines``.

    Examples
    --------
    >>> img = np.zeros((8, 8, 3), np.uint8)
    >>> same = np.array([[[1.0, 1.0], [6.0, 1.0]]])
    >>> bool((normalise_image(img, same, same) == img).all())
    True
    """
    m = beier_neely_map(image.shape, dst_lines=target_lines, src_lines=lines, a=a, b=b, p=p)
    if image.ndim == 3 and image.shape[2] == 4:
        # RGBA: resampled premultiplied, so transparent pixels lend no colour to the edge
        import cv2

        from .alpha import warp_rgba

        flags = {"linear": cv2.INTER_LINEAR, "nearest": cv2.INTER_NEAREST, "cubic": cv2.INTER_CUBIC}
        if interpolation not in flags:
            raise ValueError(f"unknown interpolation {interpolation!r}; valid: {', '.join(flags)}")
        return warp_rgba(image, m, interpolation=flags[interpolation])
    return warp(image, m, interpolation=interpolation)


def with_images(nb: NormalisedBank, images: Dict[str, np.ndarray]) -> NormalisedBank:
    """A copy of ``nb`` with other images (used by tests and previews)."""
    return replace(nb, images=images)
