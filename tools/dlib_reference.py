"""Reference landmarks from an independent model: dlib's 68-point shape predictor.

Used to check lipsync's face mesh on real frames (tests and the ``face`` bench figure). dlib
is not a dependency of lipsync; install it only to remake the reference::

    pip install dlib-bin face_recognition_models
    python tools/dlib_reference.py tests/data/grid-s1/*.mpg --every 3 -o tests/data/grid-s1/dlib68.json

The output maps each video's file name to ``{"frames": [...], "points": [[[x, y] * 68] ...]}``
(pixel centres at integers, frames where dlib finds no face left out).
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path


def reference(paths, every: int):
    import dlib
    import face_recognition_models

    from lipsync.face.video import read_video

    detector = dlib.get_frontal_face_detector()
    predictor = dlib.shape_predictor(face_recognition_models.pose_predictor_model_location())
    out = {}
    for path in paths:
        frames, points = [], []
        for i, frame in enumerate(read_video(path)):
            if i % every:
                continue
            faces = detector(frame, 1)
            if not faces:
                continue
            face = max(faces, key=lambda r: r.width() * r.height())
            shape = predictor(frame, face)
            frames.append(i)
            points.append([[shape.part(k).x, shape.part(k).y] for k in range(68)])
        out[Path(path).name] = {"frames": frames, "points": points}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("videos", nargs="+")
    ap.add_argument("--every", type=int, default=1, help="every Nth frame")
    ap.add_argument("-o", "--output", required=True)
    args = ap.parse_args()
    data = reference(args.videos, args.every)
    tmp = args.output + ".tmp"
    with open(tmp, "w") as f:
        json.dump({"model": "dlib shape_predictor_68_face_landmarks", "every": args.every, "videos": data}, f,
                  separators=(",", ":"))
    os.replace(tmp, args.output)


if __name__ == "__main__":
    main()
