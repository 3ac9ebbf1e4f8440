"""Making the samples from the footage a bank is made from (:func:`write_samples`).

Every frame of every clip with a face found and a still head (stabilisation residual under
:data:`MAX_RESIDUAL`) becomes a sample::

    frame f of clip v --stabilisation (lipsync.videobank.stabilise) + pose onto the rest
    picture's nose and cheeks (lipsync.composite.face.pose_onto)--> A_f: source -> bank pixels
    lower-face mask box (bank pixels) --A_f^-1--> box in source pixels --> crop at an integer
    offset, one size for all (no resample) --> samples.mp4
    A_f composed with the crop's shift --> the table's ``affine``; lips, opening, phones --> samples.npz

Examples
--------
>>> import numpy as np
>>> crop_origin(np.array([[1.0, 0, -10], [0, 1.0, -20]]), (5, 6, 15, 16), (12, 12))
(14, 25)
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import cv2
import numpy as np

from .store import CROP_CRF, FORMAT_VERSION, MAX_SAMPLES, TABLE_NAME, VIDEO_NAME, lip_points

#: A frame whose still points sit farther than this from the reference pose after the
#: stabilisation (eye distances) is left out: the head turned, and a 2-D warp of its mouth
#: would not sit on the plate's face (GRID s1's frames: median 0.006, 99th percentile 0.02).
MAX_RESIDUAL = 0.04
#: Pixels of margin around the mask's box, each side: bilinear/bicubic sampling at the
#: box's edge reads up to two pixels beyond it.
MARGIN = 3
#: The appearance thumbnail (W, H): 16x12 grey pixels of the mouth box keep the teeth,
#: the lips' outline and the dark of an open mouth, and cost 192 numbers per sample.
THUMB = (16, 12)
#: The samples' mask: the lower face of the rest picture's mesh shrunk by this many eye
#: distances (lipsync.composite.face.mask_from_mesh's grow, negative). The plate's mask is
#: grown 0.15 *outside* the jaw for pictures pasted onto the plate; a sample pasted so far
#: out brings its own moment's background and collar beside the plate's cheek (a visible
#: stripe along the jaw on GRID s1), and so does one shrunk by only 0.05 where the sample's
#: head had turned a little (docs/strip-dub.png, bbaf3s frame 18 on bgbb3a's plate): inside
#: by 0.15 it brings only face.
SAMPLE_GROW = -0.05
#: ... and held inside an ellipse about the mouth's centre with these semi-axes (eye
#: distances, horizontal and vertical): the lower-face outline's top corners reach the
#: cheeks' edge beside the nose, where a sample whose head had turned a little shows
#: background (docs/strip-dub.png: bbaf3s frame 18 on bgbb3a's plate, a blue streak at the
#: left cheek with the outline alone, also when shrunk by 0.15). 0.75 keeps the mouth
#: corners (0.45-0.5 from the centre) and the cheeks beside them; 1.1 down reaches the chin.
ELLIPSE = (0.75, 1.1)
#: Its feather, eye distances: wider than the plate mask's 0.12, so that what differs
#: between a sample's moment and the plate's (light on the skin, a shadow) fades out.
SAMPLE_FEATHER = 0.12
#: A phone label that means silence, as the table stores it.
SILENCE = "sil"


def crop_origin(to_bank: np.ndarray, box: Tuple[int, int, int, int], size: Tuple[int, int]) -> Tuple[int, int]:
    """The integer top-left corner, in source pixels, of a crop of ``size`` (w, h) centred on
    the bank-pixel ``box`` (x0, y0, x1, y1) mapped back through ``to_bank`` (source -> bank)."""
    from ..composite.plate import pose_inverse

    inv = pose_inverse(to_bank)
    x0, y0, x1, y1 = box
    c = np.array([(x0 + x1 - 1) / 2, (y0 + y1 - 1) / 2]) @ inv[:, :2].T + inv[:, 2]
    return int(np.floor(c[0] - (size[0] - 1) / 2 + 0.5)), int(np.floor(c[1] - (size[1] - 1) / 2 + 0.5))


def mouth_ellipse(mesh: np.ndarray, shape: Tuple[int, int]) -> np.ndarray:
    """float32 ``(H, W)``: 1 inside the :data:`ELLIPSE` about the mouth corners' middle of a face
    ``mesh``, falling smoothly to 0 at its edge over :data:`SAMPLE_FEATHER` eye distances.

    Examples
    --------
    >>> from lipsync.face import topology as T
    >>> p = np.zeros((468, 2)); p[[61, 291]] = [[40, 60], [60, 60]]
    >>> p[list(T.EYE_UPPER_L + T.EYE_LOWER_L)] = [30, 20]; p[list(T.EYE_UPPER_R + T.EYE_LOWER_R)] = [70, 20]
    >>> m = mouth_ellipse(p, (100, 100))
    >>> float(m[60, 50]), float(m[60, 5]), float(m[60, 95])
    (1.0, 0.0, 0.0)
    """
    from ..face.measure import eye_distance

    p = np.asarray(mesh, np.float64)
    d = float(eye_distance(p[None])[0])
    cx, cy = p[[61, 291], :2].mean(axis=0)
    ys, xs = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    r = np.hypot((xs - cx) / (ELLIPSE[0] * d), (ys - cy) / (ELLIPSE[1] * d))
    t = np.clip((1.0 - r) / (SAMPLE_FEATHER / max(ELLIPSE)), 0.0, 1.0)
    return (t * t * (3.0 - 2.0 * t)).astype(np.float32)


def mask_box(mask: np.ndarray) -> Tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)`` of the mask's non-zero pixels, with :data:`MARGIN` (exclusive ends)."""
    from ..composite.plate import MASK_FLOOR

    ys, xs = np.nonzero(mask >= MASK_FLOOR)
    h, w = mask.shape
    return (max(0, int(xs.min()) - MARGIN), max(0, int(ys.min()) - MARGIN),
            min(w, int(xs.max()) + 1 + MARGIN), min(h, int(ys.max()) + 1 + MARGIN))


def to_bank_matrices(footage, framing, rest_mesh: np.ndarray) -> Dict[Tuple[int, int], np.ndarray]:
    """(clip, frame) -> the 2x3 source -> bank pixels of every usable frame: the stabilisation,
    then the similarity putting its nose base and cheeks on the rest picture's (as the bank's
    own pictures are put on the plate: lipsync.videobank.make.cut_and_choose)."""
    from ..composite.face import pose_onto
    from ..composite.plate import compose

    out = {}
    for v, (tr, reg) in enumerate(zip(footage.tracks, footage.regs)):
        ok = np.asarray(tr.found, bool) & np.isfinite(reg.residual) & (np.nan_to_num(reg.residual, nan=1.0)
                                                                       <= MAX_RESIDUAL)
        for f in np.nonzero(ok)[0]:
            m = framing.matrix(reg, int(f))
            pts = tr.points[f][:, :2] @ m[:, :2].T + m[:, 2]
            out[(v, int(f))] = compose(pose_onto(pts, rest_mesh), m)
    return out


#: Labels that mean silence in the aligners' and readers' phone tiers.
SILENCE_LABELS = ("", "sil", "sp", "spn", "pau", "<sil>", "h#", "epi")


def phone_label(label: str) -> str:
    """A phone label as the table stores it: upper case, :data:`SILENCE` for silence.

    Examples
    --------
    >>> phone_label(" aa "), phone_label("sp")
    ('AA', 'sil')
    """
    lab = label.strip()
    return SILENCE if lab.lower() in SILENCE_LABELS else lab.upper()


def phone_rows(phones, n: int, fps: float) -> Tuple[List[str], List[str], List[str]]:
    """Per frame of a clip, the phone said at its time (``i / fps``) and the phones before and after."""
    segs = [(s.start, s.end, phone_label(s.label)) for s in phones.segments]
    starts = np.array([s[0] for s in segs]) if segs else np.zeros(0)
    cur, prev, nxt = [], [], []
    for i in range(n):
        k = int(np.searchsorted(starts, i / fps, side="right")) - 1
        if k < 0 or k >= len(segs) or i / fps >= segs[k][1]:
            cur.append(SILENCE), prev.append(SILENCE), nxt.append(SILENCE)
            continue
        cur.append(segs[k][2])
        prev.append(segs[k - 1][2] if k > 0 else SILENCE)
        nxt.append(segs[k + 1][2] if k + 1 < len(segs) else SILENCE)
    return cur, prev, nxt


def write_samples(folder: Path, footage, framing, rest_mesh: np.ndarray, rest_image: np.ndarray, *,
                  pictures: Optional[Dict[str, np.ndarray]] = None, quiet: bool = True) -> str:
    """Write ``samples.mp4`` and ``samples.npz`` into ``folder`` and return the bank.yaml line naming them.

    ``framing`` is the bank pictures' (:class:`~lipsync.videobank.stabilise.Framing`),
    ``rest_mesh`` the rest picture's face mesh (bank pixels) and ``rest_image`` the picture
    (what the plate's colour is matched to: each sample's colour gain is measured against it).
    ``pictures`` (viseme -> its picture's face mesh, bank pixels) gives the table each
    picture's lip opening (``pictures``, ``picture_opening``).
    """
    from ..composite.face import mask_from_mesh

    mask = mask_from_mesh([rest_mesh], rest_image.shape[:2], grow=SAMPLE_GROW, feather=SAMPLE_FEATHER)
    mask *= mouth_ellipse(rest_mesh, mask.shape)
    to_bank = to_bank_matrices(footage, framing, rest_mesh)
    keys = sorted(to_bank)
    if len(keys) > MAX_SAMPLES:
        warnings.warn(f"{footage.names}: {len(keys)} usable frames; the first {MAX_SAMPLES} are kept as "
                      f"samples", UserWarning, stacklevel=3)
        keys = keys[:MAX_SAMPLES]
    box = mask_box(mask)
    size = crop_size(to_bank, keys, box)
    origins = {k: crop_origin(to_bank[k], box, size) for k in keys}
    crops = _write_crops(folder / VIDEO_NAME, footage, keys, origins, size, quiet=quiet)
    table = _table(footage, keys, to_bank, origins, crops, box)
    table["mask"] = np.round(mask * 255).astype(np.uint8)
    table["gain"] = colour_gains(crops, table["affine"], rest_image, rest_mesh, mask)
    if pictures:
        from ..face.measure import lip_opening

        names = sorted(pictures)
        table["pictures"] = np.array(names)
        table["picture_opening"] = np.array([float(lip_opening(np.asarray(pictures[v]))) for v in names])
    table.update(lip_model(footage, table))
    buf = io.BytesIO()
    np.savez_compressed(buf, **table)
    (folder / TABLE_NAME).write_bytes(buf.getvalue())
    return f"samples: {{video: {VIDEO_NAME}, table: {TABLE_NAME}}}\n"


def lip_model(footage, table) -> Dict[str, np.ndarray]:
    """The audio lip model's arrays (:mod:`lipsync.samples.lipmodel`) fitted on the footage's
    sound and the table's lips; none when no clip has sound (the target then comes from the
    phones alone)."""
    from .lipmodel import fit_clips

    model = fit_clips([s.path for s in footage.sources], table["fps"].tolist(), table)
    return {} if model is None else model.arrays()


def crop_size(to_bank, keys, box) -> Tuple[int, int]:
    """One crop size (w, h), even (H.264's 4:2:0), holding every frame's box in source pixels."""
    from ..composite.plate import pose_inverse

    x0, y0, x1, y1 = box
    corners = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]], np.float64)
    w = h = 0.0
    for k in keys:
        inv = pose_inverse(to_bank[k])
        p = corners @ inv[:, :2].T + inv[:, 2]
        w, h = max(w, np.ptp(p[:, 0])), max(h, np.ptp(p[:, 1]))
    w, h = int(np.ceil(w)) + 2, int(np.ceil(h)) + 2
    return w + w % 2, h + h % 2


def _cut(frame: np.ndarray, origin: Tuple[int, int], size: Tuple[int, int]) -> np.ndarray:
    """The ``size`` crop at ``origin``, edge pixels repeated where it leaves the frame (no resample)."""
    (x, y), (w, h) = origin, size
    fh, fw = frame.shape[:2]
    pad = max(0, -x, -y, x + w - fw, y + h - fh)
    if pad:
        frame = cv2.copyMakeBorder(np.ascontiguousarray(frame), pad, pad, pad, pad, cv2.BORDER_REPLICATE)
        x, y = x + pad, y + pad
    return frame[y:y + h, x:x + w]


def _write_crops(path: Path, footage, keys, origins, size, *, quiet: bool) -> List[np.ndarray]:
    """Decode every clip once, cut the samples' crops, encode them; returns the crops as decoded
    again from the file (what a render will read: the appearance is measured on those)."""
    from ..encode import open_writer
    from ..face.video import read_video
    from .store import read_crops

    wanted: Dict[int, set] = {}
    for v, f in keys:
        wanted.setdefault(v, set()).add(f)
    fps = float(footage.tracks[0].fps)
    with open_writer(path, fps=fps, size=size, format="mp4", crf=CROP_CRF, preset="talking-head", quiet=True,
                     frames=len(keys)) as writer:
        for v, s in enumerate(footage.sources):
            frames = wanted.get(v, set())
            if not frames:
                continue
            last = max(frames)
            for i, frame in enumerate(read_video(s.path, info=s.info)):
                if i in frames:
                    writer.write(np.ascontiguousarray(_cut(frame, origins[(v, i)], size)))
                if i >= last:
                    break
    return list(read_crops(path, len(keys)))


def _table(footage, keys, to_bank, origins, crops, box) -> Dict[str, np.ndarray]:
    """The table's arrays (see :mod:`lipsync.samples.store`)."""
    from ..composite.plate import compose
    from ..face import measure as M

    n = len(keys)
    clip = np.array([k[0] for k in keys], np.int32)
    frame = np.array([k[1] for k in keys], np.int32)
    new_run = np.ones(n, bool)
    new_run[1:] = (clip[1:] != clip[:-1]) | (frame[1:] != frame[:-1] + 1)
    affine = np.stack([compose(to_bank[k], np.array([[1.0, 0, origins[k][0]], [0, 1.0, origins[k][1]]]))
                       for k in keys])
    pts = np.stack([footage.tracks[v].points[f] for v, f in keys]).astype(np.float64)
    lips = np.stack([p[list(lip_points()), :2] @ a[:, :2].T + a[:, 2] for p, a in
                     zip(pts, [to_bank[k] for k in keys])])
    rows = [phone_rows(sp.phones, len(tr), tr.fps) for sp, tr in zip(footage.speeches, footage.tracks)]
    labels = [(rows[v][0][f], rows[v][1][f], rows[v][2][f]) for v, f in keys]
    vocab = sorted({x for t in labels for x in t} | {SILENCE})
    index = {p: i for i, p in enumerate(vocab)}
    return {
        "version": np.array(FORMAT_VERSION), "clips": np.array([s.name for s in footage.sources]),
        "fps": np.array([float(tr.fps) for tr in footage.tracks]), "clip": clip, "frame": frame,
        "run": np.cumsum(new_run).astype(np.int32) - 1,
        "opening": M.lip_opening(pts).astype(np.float32), "width": M.mouth_width(pts).astype(np.float32),
        "protrusion": M.lip_protrusion(pts).astype(np.float32), "lips": lips.astype(np.float32),
        "phones": np.array(vocab), "phone": np.array([index[t[0]] for t in labels], np.int16),
        "prev": np.array([index[t[1]] for t in labels], np.int16),
        "next": np.array([index[t[2]] for t in labels], np.int16),
        "origin": np.array([origins[k] for k in keys], np.int32).reshape(-1, 2),
        "affine": affine, "appearance": appearance(crops, affine, box),
    }


def colour_gains(crops, affine: np.ndarray, rest_image: np.ndarray, rest_mesh: np.ndarray,
                 mask: np.ndarray) -> np.ndarray:
    """``(N, 3)`` float32: per sample, the per-channel gain taking its colour to the rest
    picture's on the skin under the nose (inside the mask, above the upper lip: skin in every
    frame, whatever the mouth does), as :func:`lipsync.composite.plate.plate_colour` measures
    the plate's; clipped to :data:`lipsync.composite.face.GAIN_RANGE`."""
    from ..composite.face import GAIN_RANGE

    h, w = mask.shape
    where = (mask > 0.5) & (np.arange(h)[:, None] < float(rest_mesh[0, 1]))
    if not where.any():
        return np.ones((len(crops), 3), np.float32)
    ys, xs = np.nonzero(where)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    sub = where[y0:y1, x0:x1]
    theirs = rest_image[y0:y1, x0:x1, :3][sub].astype(np.float64).mean(axis=0)
    shift = np.array([[1.0, 0, -x0], [0, 1.0, -y0]])
    from ..composite.plate import compose

    out = np.empty((len(crops), 3), np.float32)
    for i, (c, a) in enumerate(zip(crops, affine)):
        img = cv2.warpAffine(np.ascontiguousarray(c), compose(shift, a), (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_REPLICATE)
        out[i] = np.clip(theirs / np.maximum(img[sub].astype(np.float64).mean(axis=0), 1.0), *GAIN_RANGE)
    return out


def appearance(crops, affine: np.ndarray, box) -> np.ndarray:
    """``(N, 192)`` float16 (a thousandth of grey is finer than the join cost tells apart; half
    the table's size): each crop in bank pixels over ``box``, grey, shrunk to :data:`THUMB`,
    its mean removed, over 255 (the selection's appearance distance compares these)."""
    from ..composite.plate import compose

    x0, y0, x1, y1 = box
    shift = np.array([[1.0, 0, -x0], [0, 1.0, -y0]])
    out = np.empty((len(crops), THUMB[0] * THUMB[1]), np.float32)
    for i, (c, a) in enumerate(zip(crops, affine)):
        img = cv2.warpAffine(np.ascontiguousarray(c), compose(shift, a), (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_REPLICATE)
        g = cv2.resize(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), THUMB, interpolation=cv2.INTER_AREA).astype(np.float32)
        out[i] = (g - g.mean()).ravel() / 255.0
    return out.astype(np.float16)
