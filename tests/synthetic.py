"""A synthetic subject drawn from parameters, so every in-between has a known truth.

The "mouth" is an anti-aliased filled ellipse with half-width ``rx`` and half-height
``ry`` centred on a fixed point, on a background with static features (eyes and a nose
bar) that never move. Control lines run along the ellipse's axes and its quarter chords,
mirror-symmetric about the vertical axis, plus static anchors on the eyes and nose.
Drawing the ellipse at interpolated (rx, ry) gives the true in-between frame.
"""

from __future__ import annotations

from pathlib import Path
from typing import Dict, Tuple

import numpy as np
import yaml

SIZE = (160, 192)          # (H, W); width even, so the axis is at x = 95.5
CENTRE = (95.5, 100.0)     # ellipse centre (x, y) on the mirror axis
SUPERSAMPLE = 4


def _coverage(h: int, w: int, inside) -> np.ndarray:
    """Fraction of each pixel inside a region, by 4x4 supersampling (anti-aliasing)."""
    s = SUPERSAMPLE
    offs = (np.arange(s) + 0.5) / s - 0.5
    ys = (np.arange(h)[:, None] + offs[None, :]).reshape(-1)
    xs = (np.arange(w)[:, None] + offs[None, :]).reshape(-1)
    cov = inside(xs[None, :], ys[:, None]).astype(np.float64)
    return cov.reshape(h, s, w, s).mean(axis=(1, 3))


def draw(rx: float, ry: float) -> np.ndarray:
    """RGB image of the subject with mouth half-axes (rx, ry)."""
    h, w = SIZE
    cx, cy = CENTRE
    img = np.empty((h, w, 3), np.float64)
    # Background: a smooth vertical gradient, so misplaced pixels show.
    img[:] = np.linspace(200, 150, h)[:, None, None] * np.array([1.0, 0.85, 0.7])
    for ex in (cx - 40, cx + 40):  # static eyes
        cov = _coverage(h, w, lambda x, y, ex=ex: (x - ex) ** 2 + (y - 40) ** 2 <= 8 ** 2)
        img = img * (1 - cov[..., None]) + cov[..., None] * np.array([30.0, 30.0, 60.0])
    nose = _coverage(h, w, lambda x, y: (np.abs(x - cx) <= 3) & (y >= 50) & (y <= 75))
    img = img * (1 - nose[..., None]) + nose[..., None] * np.array([150.0, 100.0, 90.0])
    mouth = _coverage(h, w, lambda x, y: ((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1.0)
    # The mouth has a vertical colour ramp so that vertical motion is visible inside it.
    ramp = np.clip((np.arange(h) - (cy - ry)) / (2 * ry), 0, 1)[:, None, None]
    inner = np.array([120.0, 20.0, 30.0]) * (1 - ramp) + np.array([240.0, 200.0, 200.0]) * ramp
    img = img * (1 - mouth[..., None]) + mouth[..., None] * inner
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def lines(rx: float, ry: float) -> Dict[str, Tuple[Tuple[float, float], Tuple[float, float]]]:
    """Named control lines for the subject with mouth half-axes (rx, ry)."""
    cx, cy = CENTRE
    k = np.sqrt(0.5)
    out = {
        "width": ((cx - rx, cy), (cx + rx, cy)),
        "height": ((cx, cy - ry), (cx, cy + ry)),
        "upper_l": ((cx - rx, cy), (cx - k * rx, cy - k * ry)),
        "upper_r": ((cx + rx, cy), (cx + k * rx, cy - k * ry)),
        "lower_l": ((cx - rx, cy), (cx - k * rx, cy + k * ry)),
        "lower_r": ((cx + rx, cy), (cx + k * rx, cy + k * ry)),
        "nose": ((cx, 50.0), (cx, 75.0)),
        "eye_l": ((cx - 48, 40.0), (cx - 32, 40.0)),
        "eye_r": ((cx + 48, 40.0), (cx + 32, 40.0)),
        "chin": ((cx - 30, 150.0), (cx + 30, 150.0)),
        # static anchors near the image edges, as a real bank's face outline: they keep
        # the flow near zero away from the mouth
        "brow": ((cx - 60, 15.0), (cx + 60, 15.0)),
        "cheek_l": ((cx - 85, 40.0), (cx - 85, 140.0)),
        "cheek_r": ((cx + 85, 40.0), (cx + 85, 140.0)),
    }
    return {n: (tuple(map(float, p)), tuple(map(float, q))) for n, (p, q) in out.items()}


#: Viseme name -> mouth half-axes (rx, ry).
SHAPES = {"X": (30.0, 4.0), "A": (26.0, 3.0), "O": (22.0, 20.0), "E": (42.0, 10.0)}


def write_bank(folder: Path, shapes=None, *, symmetry: bool = True) -> Path:
    """Write a bank of the synthetic subject into ``folder``; returns the folder."""
    import cv2

    shapes = shapes or SHAPES
    folder.mkdir(parents=True, exist_ok=True)
    visemes = {}
    for name, (rx, ry) in shapes.items():
        cv2.imwrite(str(folder / f"{name}.png"), cv2.cvtColor(draw(rx, ry), cv2.COLOR_RGB2BGR))
        visemes[name] = {"image": f"{name}.png",
                         "lines": {n: [list(p), list(q)] for n, (p, q) in lines(rx, ry).items()}}
    spec = {"name": "synthetic", "rest": "X", "symmetry": symmetry, "visemes": visemes}
    (folder / "bank.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    return folder


#: A synthetic bank with Rhubarb's nine shape names, for end-to-end tests with the default map.
RHUBARB_SHAPES = {
    "X": (30.0, 4.0), "A": (28.0, 2.5), "B": (34.0, 7.0), "C": (38.0, 14.0), "D": (40.0, 24.0),
    "E": (30.0, 16.0), "F": (18.0, 12.0), "G": (34.0, 5.0), "H": (36.0, 18.0),
}
