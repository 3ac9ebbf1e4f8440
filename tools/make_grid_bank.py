"""visemes/grid-s1/: the real subject, made by ``lipsync init --video`` from GRID's speaker s1.

The ten sentences of :data:`lipsync.bench.grid.BANK_CLIPS` (30 s of video, every viseme of
both shipped maps) are linked into a scratch folder with each one's transcript beside it as
``NAME.txt`` (GRID's ``.align`` words), exactly as a user would lay out their own videos,
and the command is run on them. GRID's attribution (CC BY 4.0) is written beside the
pictures, and the preview sheet is left out of the shipped folder (``lipsync preview``
draws it again).

Usage (from the repository root)::

    .venv/bin/python tools/make_grid_bank.py            # rewrites visemes/grid-s1/
    .venv/bin/python tools/make_grid_bank.py /tmp/grid  # or writes elsewhere
    .venv/bin/python tools/make_grid_bank.py --lip-model-only   # only (re)fit the audio lip
        # model into visemes/grid-s1/samples.npz (lipsync.samples.lipmodel; what init --video
        # now fits when it writes the samples), the rest of the bank left as it is
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from lipsync.bench import grid
from lipsync.cli import main as lipsync

ROOT = Path(__file__).resolve().parents[1]

SOURCE = """# GRID speaker s1: a subject made from real video

Nine pictures of one speaker, one per mouth shape of `english-to-rhubarb`, chosen from ten
sentences of real video by `lipsync init --video` (`tools/make_grid_bank.py`; the frames
chosen, their times and scores are in `init-report.json`). The rest picture (X, the *plate*,
`face_plate` in the report) is a video frame rotated, scaled and shifted onto one head pose
and cropped around the head. Every other picture is that plate outside the lower face; inside
it, the mouth, jaw and chin of its own chosen frame, moved onto the plate's pose, colour
matched on the skin around it and blended in with a feathered mask (one face: see
docs/make-a-subject.md). Nothing else was changed.

`samples.mp4` and `samples.npz` are the mouth samples (docs/formats.md, "Mouth samples"):
the lower face of every frame of the ten sentences, cut from the video at integer offsets
(not resampled) and stored at H.264 crf 8, with each frame's lip measures, phones and its
place in the sentence. `lipsync render` and `lipsync dub` select one per frame
(`--samples off`: the nine pictures, morphed).

The sentences: {clips}.

From the GRID audio-visual speech corpus: M. Cooke, J. Barker, S. Cunningham and X. Shao
(2006), "An audio-visual corpus for speech perception and automatic speech recognition",
Journal of the Acoustical Society of America 120(5), 2421-2424. The corpus is released under
the Creative Commons Attribution 4.0 licence (CC BY 4.0): copy, adapt and redistribute with
this attribution. The video files are as redistributed in the public repository TVR28/LipNet
(data/s1 and data/alignments/s1).
"""


def make(out: Path) -> int:
    with tempfile.TemporaryDirectory() as tmp:
        videos = []
        for name in grid.BANK_CLIPS:
            link = Path(tmp) / f"{name}.mpg"
            link.symlink_to(grid.video(name).resolve())
            link.with_suffix(".txt").write_text(grid.transcript(name) + "\n")
            videos.append(str(link))
        code = lipsync(["init", str(out), "--video", *videos, "--force"])
    if code:
        return code
    (out / "preview.png").unlink(missing_ok=True)
    (out / "SOURCE.md").write_text(SOURCE.format(clips=", ".join(
        f"`{c}` (\"{grid.transcript(c)}\")" for c in grid.BANK_CLIPS)))
    return 0


def lip_model_only(out: Path) -> int:
    """Fit the audio lip model on the bank's own sentences' sound and write it into its samples table."""
    import io
    import os

    import numpy as np

    from lipsync.samples import read_table
    from lipsync.samples.lipmodel import ARRAYS, fit_clips

    path = out / "samples.npz"
    table = {k: v for k, v in read_table(path).items() if k not in dict(ARRAYS)}
    model = fit_clips([grid.video(Path(str(c)).stem) for c in table["clips"]], table["fps"].tolist(), table)
    table.update(model.arrays())
    buf = io.BytesIO()
    np.savez_compressed(buf, **table)
    tmp = path.with_suffix(".npz.tmp")
    tmp.write_bytes(buf.getvalue())
    os.replace(tmp, path)
    read_table(path)
    return 0


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--lip-model-only"]
    target = Path(args[0]) if args else ROOT / "visemes" / "grid-s1"
    sys.exit(lip_model_only(target) if "--lip-model-only" in sys.argv else make(target))
