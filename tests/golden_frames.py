"""Hashes of opaque frames, to prove that transparency support changed none of them.

``python tests/golden_frames.py`` (from the repository) writes
``tests/data/golden/opaque-frames.json``: sha256 of the pixels of frames rendered from the
shipped toon and the synthetic ellipse bank by every method and frame kernel, of the three
parts ``Renderer.parts`` returns, of a preview sheet and a morph strip, and of the decoded
frames of a short clip written as PNGs. The file in the repository was made by the code
before RGBA banks existed (issue 18); tests/test_alpha.py renders the same cases with the
current code and compares.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
GOLDEN = HERE / "data" / "golden" / "opaque-frames.json"
sys.path.insert(0, str(HERE))

#: Pairs and alphas rendered per method: a closing, an opening and neighbours, off the
#: table nodes (0.13, 0.77) and on one (0.5).
PAIRS = {"toon": [("X", "A"), ("A", "D"), ("D", "E"), ("F", "B"), ("H", "C")],
         "ellipse": [("X", "O"), ("E", "A"), ("O", "E")]}
ALPHAS = (0.13, 0.5, 0.77)


def digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(repr((a.shape, a.dtype.str)).encode())
        h.update(a.data)
    return h.hexdigest()


def banks(workdir: Path):
    """The two opaque banks, copied so that their flow stores start empty."""
    import synthetic
    from lipsync.banks.bank import Bank

    toon = workdir / "toon"
    shutil.copytree(ROOT / "visemes" / "toon", toon, ignore=shutil.ignore_patterns("store", ".lipsync*"))
    ellipse = synthetic.write_bank(workdir / "ellipse")
    # refine: false -- the hashes were taken before refined flows (issue 22) existed, and what
    # they prove (transparency changed no opaque frame) is about the renderer, not the flows
    for folder in (toon, ellipse):
        y = folder / "bank.yaml"
        y.write_text(y.read_text().replace("\nvisemes:", "\nrefine: false\nvisemes:", 1))
    return {"toon": Bank.load(toon), "ellipse": Bank.load(ellipse)}


def cases(workdir: Path):
    """(name, digest) of every case, in a fixed order."""
    from lipsync.pipeline.clip import render_clip
    from lipsync.encode.preview import feature_lines, preview_sheet, strip
    from lipsync.morphing.render import Renderer, available_kernels

    out = {}
    for bname, bank in banks(workdir).items():
        variants = [("flow", k) for k in available_kernels()] + [(m, None) for m in ("splat", "beier-neely", "dissolve")]
        for method, kernel in variants:
            r = Renderer(bank, method=method, kernel=kernel)
            label = f"{bname}/{method}" + (f"/{kernel}" if kernel else "")
            for a, b in PAIRS[bname]:
                for t in ALPHAS:
                    out[f"{label}/{a}-{b}@{t}"] = digest(r.render(a, b, t))
            a, b = PAIRS[bname][1]
            out[f"{label}/parts/{a}-{b}@0.5"] = digest(*r.parts(a, b, 0.5))
        named = {v: feature_lines(bank.line_names, bank.lines[v]) for v in bank.names}
        out[f"{bname}/preview-sheet"] = digest(preview_sheet({v: bank.images[v] for v in bank.names}, named, tile=160))
        r = Renderer(bank, method="flow")
        a, b = PAIRS[bname][1]
        cols = [r.parts(a, b, float(t)) for t in np.linspace(0, 1, 4)]
        out[f"{bname}/morph-strip"] = digest(strip([[c[0] for c in cols], [c[2] for c in cols], [c[1] for c in cols]],
                                                   row_labels=["a", "blend", "b"], tile=120))
        if bname == "toon":
            frames = workdir / "frames"
            render_clip(ROOT / "samples" / "hello.phn", frames, bank=bank, format="png", quiet=True)
            decoded = [cv2.imread(str(p), cv2.IMREAD_UNCHANGED) for p in sorted(frames.iterdir())]
            out["toon/clip-hello-png"] = digest(*decoded)
    return out


def main() -> None:
    with tempfile.TemporaryDirectory() as d:
        got = cases(Path(d))
    GOLDEN.parent.mkdir(parents=True, exist_ok=True)
    GOLDEN.write_text(json.dumps(got, indent=1, sort_keys=True) + "\n")
    print(f"wrote {len(got)} hashes to {GOLDEN}")


if __name__ == "__main__":
    main()
