"""Face detection and the 468-point face mesh, offline, with Google's LiteRT runtime.

Two MediaPipe models ship inside the package (``models/``, Apache 2.0, see SOURCE.md there):
BlazeFace short-range finds faces, and the face mesh places 468 points on a face given a
square crop around it. MediaPipe's own graphs do the pre- and post-processing in C++
calculators; this module is that work, written out:

1. **Detection** (:func:`_decode_detections`): the picture is letterboxed to 128×128 (aspect
   kept, zero padding) and scaled to [-1, 1]. The model scores 896 fixed SSD anchors
   (16×16 cells × 2 at stride 8, 8×8 cells × 6 at stride 16) and regresses, per anchor, a box
   and six keypoints (eyes, nose tip, mouth, ears) as offsets in input pixels from the
   anchor's centre. Boxes scoring ≥ :data:`MIN_DETECTION_SCORE` are merged by *weighted*
   non-maximum suppression (overlapping boxes averaged by score, as MediaPipe does: steadier
   than keeping the single best box).
2. **Region of interest** (:class:`Roi`): a square rotated so that the eyes are level, 1.5×
   the face box's longer side (room for the chin and forehead). From a detection it is built
   on the box and the eye keypoints; from a previous frame's mesh on the points' extent in the
   eyes' frame (that is how video is tracked without detecting again).
3. **Mesh** (:meth:`FaceMesh.landmarks_in`): the ROI is resampled to 192×192 (bilinear),
   scaled to [0, 1], and the model gives 468 ``(x, y, z)`` in crop pixels plus a face score;
   the points are mapped back through the ROI's transform to image pixels (``z`` in the
   same pixel scale, smaller = nearer the camera).

Coordinates follow lipsync's convention (DESIGN.md): pixel centres at integers.

Examples
--------
>>> import numpy as np
>>> mesh = FaceMesh()
>>> mesh.detect(np.zeros((120, 160, 3), np.uint8))   # nothing to find in a black picture
[]
"""

from __future__ import annotations

import math
import os
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Tuple

import cv2
import numpy as np

from ..errors import InputError
from .topology import EYE_CORNERS_L, EYE_CORNERS_R

MODEL_DIR = Path(__file__).resolve().parent / "models"
DETECTOR_MODEL = MODEL_DIR / "face_detection_short_range.tflite"
MESH_MODEL = MODEL_DIR / "face_landmark.tflite"

#: Detector input side (the model's fixed input).
DETECTOR_SIZE = 128
#: Mesh input side.
MESH_SIZE = 192
#: Anchors per cell at each stride of the short-range model (its SSD configuration: four
#: layers with strides 8, 16, 16, 16, two anchors each; layers of equal stride share a grid).
_ANCHOR_LAYOUT = ((8, 2), (16, 6))
#: BlazeFace keeps boxes scoring at least this (MediaPipe's default for this model).
MIN_DETECTION_SCORE = 0.5
#: Boxes overlapping more than this (intersection over union) are one face.
NMS_OVERLAP = 0.3
#: Raw scores are clipped before the sigmoid (MediaPipe's ``score_clipping_thresh``).
_SCORE_CLIP = 100.0
#: The face crop is this many times the face's extent (MediaPipe's face-mesh ROI scale):
#: room for the chin when the jaw drops and for the forehead.
ROI_SCALE = 1.5
#: Below this face score the mesh has lost the face (MediaPipe's min_tracking_confidence).
MIN_MESH_SCORE = 0.5
#: Keypoints of a detection: 0 = eye on the image left (the subject's right), 1 = the other eye.
_KP_EYE_LEFT, _KP_EYE_RIGHT = 0, 1


class NoFaceError(InputError):
    """No face was found in a picture (or in any frame of a video)."""


class FaceWarning(UserWarning):
    """A face was found, but something about it deserves a look (several faces, lost frames)."""


def _quiet_stderr_call(fn):
    """Run ``fn()`` with the C++ runtime's stderr chatter hidden (re-shown if it fails).

    LiteRT prints "Created TensorFlow Lite XNNPACK delegate" on every interpreter: noise in
    a command-line tool. The output is kept and printed again only if ``fn`` raises.
    """
    try:
        fd = os.dup(2)
    except OSError:
        return fn()
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            return fn()
        except BaseException:
            os.dup2(fd, 2)
            tmp.seek(0)
            os.write(2, tmp.read())
            raise
        finally:
            os.dup2(fd, 2)
            os.close(fd)


def _interpreter(path: Path, threads: int):
    try:
        from ai_edge_litert.interpreter import Interpreter
    except ImportError as e:  # pragma: no cover - a dependency of the package
        raise RuntimeError("face landmarks need Google's LiteRT runtime: pip install ai-edge-litert") from e

    def make():
        it = Interpreter(model_path=str(path), num_threads=threads)
        it.allocate_tensors()
        return it

    return _quiet_stderr_call(make)


def ssd_anchors() -> np.ndarray:
    """Centres of the short-range detector's 896 anchors, normalised to [0, 1].

    Row-major over each stride's grid, the anchors of one cell consecutive (the order of
    the model's outputs).

    Examples
    --------
    >>> a = ssd_anchors()
    >>> a.shape, a[0].tolist(), a[-1].tolist()
    ((896, 2), [0.03125, 0.03125], [0.9375, 0.9375])
    """
    out = []
    for stride, per_cell in _ANCHOR_LAYOUT:
        n = DETECTOR_SIZE // stride
        ys, xs = np.mgrid[0:n, 0:n]
        centres = np.stack([(xs + 0.5) / n, (ys + 0.5) / n], axis=-1).reshape(-1, 2)
        out.append(np.repeat(centres, per_cell, axis=0))
    return np.concatenate(out)


_ANCHORS = ssd_anchors()


@dataclass(frozen=True)
class Detection:
    """One face found by the detector, in image pixels (centres at integers).

    Attributes
    ----------
    box : numpy.ndarray
        ``[x0, y0, x1, y1]`` float64.
    keypoints : numpy.ndarray
        ``(6, 2)``: eye on the image left, the other eye, nose tip, mouth, ear on the image
        left, the other ear.
    score : float
        Detector confidence, 0–1.
    """

    box: np.ndarray
    keypoints: np.ndarray
    score: float

    @property
    def area(self) -> float:
        x0, y0, x1, y1 = self.box
        return max(0.0, x1 - x0) * max(0.0, y1 - y0)


def _iou(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    x0 = np.maximum(box[0], boxes[:, 0])
    y0 = np.maximum(box[1], boxes[:, 1])
    x1 = np.minimum(box[2], boxes[:, 2])
    y1 = np.minimum(box[3], boxes[:, 3])
    inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
    area = lambda b: (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1])  # noqa: E731
    return inter / np.maximum(area(box) + area(boxes) - inter, 1e-12)


def _decode_detections(regressors: np.ndarray, scores: np.ndarray) -> List[Tuple[np.ndarray, np.ndarray, float]]:
    """Raw model outputs → merged ``(box, keypoints, score)`` in normalised input coordinates."""
    raw = regressors.reshape(-1, 16).astype(np.float64)
    logit = np.clip(scores.reshape(-1).astype(np.float64), -_SCORE_CLIP, _SCORE_CLIP)
    prob = 1.0 / (1.0 + np.exp(-logit))
    keep = np.nonzero(prob >= MIN_DETECTION_SCORE)[0]
    if keep.size == 0:
        return []
    raw, prob, anchors = raw[keep] / DETECTOR_SIZE, prob[keep], _ANCHORS[keep]
    centre = raw[:, 0:2] + anchors
    half = raw[:, 2:4] / 2
    boxes = np.concatenate([centre - half, centre + half], axis=1)
    kps = raw[:, 4:16].reshape(-1, 6, 2) + anchors[:, None, :]
    order = np.argsort(-prob, kind="stable")
    boxes, kps, prob = boxes[order], kps[order], prob[order]
    out = []
    remaining = np.arange(len(prob))
    while remaining.size:
        overlap = _iou(boxes[remaining[0]], boxes[remaining])
        group = remaining[overlap > NMS_OVERLAP]
        group = group if group.size else remaining[:1]
        w = prob[group][:, None]
        out.append(((boxes[group] * w).sum(0) / w.sum(),
                    (kps[group] * w[:, :, None]).sum(0) / w.sum(),
                    float(prob[group[0]])))
        remaining = remaining[overlap <= NMS_OVERLAP]
    return out


@dataclass(frozen=True)
class Roi:
    """A rotated square region of an image: where the mesh looks for the face.

    Attributes
    ----------
    centre : tuple of float
        ``(x, y)`` in image pixels (centres at integers).
    size : float
        Side length in pixels.
    angle : float
        Radians; the direction of the square's x axis in the image (0 = upright face;
        positive turns towards +y, the image's down).

    Examples
    --------
    >>> r = Roi((100.0, 80.0), 192.0, 0.0)
    >>> r.to_image(np.array([[96.0, 96.0, 0.0]]))[0].tolist()   # the crop's centre
    [100.0, 80.0, 0.0]
    """

    centre: Tuple[float, float]
    size: float
    angle: float

    def _axes(self):
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.array([c, s]), np.array([-s, c])

    def crop_matrix(self, side: int) -> np.ndarray:
        """2×3 matrix taking crop pixel centres to image pixel centres (for WARP_INVERSE_MAP)."""
        ux, uy = self._axes()
        k = self.size / side
        # Crop pixel u covers [u, u+1] of the crop; its centre u + 0.5 is at the normalised
        # position (u + 0.5) / side, i.e. at centre + ((u + 0.5) / side - 0.5) * size along ux.
        origin = np.asarray(self.centre) + (0.5 * k - 0.5 * self.size) * (ux + uy)
        return np.column_stack([ux * k, uy * k, origin])

    def to_image(self, points: np.ndarray, side: int = MESH_SIZE) -> np.ndarray:
        """Crop coordinates (the model's: 0..side from the crop's edge) → image pixels."""
        ux, uy = self._axes()
        rel = points[:, :2] / side - 0.5
        xy = np.asarray(self.centre) + rel[:, :1] * self.size * ux + rel[:, 1:2] * self.size * uy
        return np.column_stack([xy, points[:, 2] * (self.size / side)])

    @classmethod
    def from_detection(cls, det: Detection) -> "Roi":
        """The mesh's region for a detected face (MediaPipe's detection-to-ROI rule)."""
        eye_a, eye_b = det.keypoints[_KP_EYE_LEFT], det.keypoints[_KP_EYE_RIGHT]
        angle = math.atan2(eye_b[1] - eye_a[1], eye_b[0] - eye_a[0])
        x0, y0, x1, y1 = det.box
        return cls(((x0 + x1) / 2, (y0 + y1) / 2), max(x1 - x0, y1 - y0) * ROI_SCALE, angle)

    @classmethod
    def from_landmarks(cls, points: np.ndarray) -> "Roi":
        """The region for the next video frame from this frame's mesh: the points' extent
        measured along the eye line and across it, so a tilted head keeps a tight square."""
        eye_a = points[list(EYE_CORNERS_L), :2].mean(axis=0)
        eye_b = points[list(EYE_CORNERS_R), :2].mean(axis=0)
        angle = math.atan2(eye_b[1] - eye_a[1], eye_b[0] - eye_a[0])
        c, s = math.cos(angle), math.sin(angle)
        u = points[:, 0] * c + points[:, 1] * s
        v = -points[:, 0] * s + points[:, 1] * c
        mu, mv = (u.min() + u.max()) / 2, (v.min() + v.max()) / 2
        centre = (mu * c - mv * s, mu * s + mv * c)
        return cls(centre, max(np.ptp(u), np.ptp(v)) * ROI_SCALE, angle)


class FaceMesh:
    """The detector and the face mesh, ready to run on RGB ``uint8`` pictures.

    One instance holds two LiteRT interpreters and reusable input buffers: create it once
    and reuse it for every frame. Not thread-safe (use one per thread).

    Parameters
    ----------
    threads : int
        Threads each interpreter may use (1: a video's frames are tracked in order anyway,
        and a second core is better spent decoding or on another video).

    Examples
    --------
    >>> import numpy as np
    >>> mesh = FaceMesh()
    >>> mesh.find(np.zeros((64, 64, 3), np.uint8), source="black.png")
    Traceback (most recent call last):
    ...
    lipsync.face.landmarks.NoFaceError: black.png: no face found
    """

    def __init__(self, *, threads: int = 1):
        self._det = _interpreter(DETECTOR_MODEL, threads)
        self._mesh = _interpreter(MESH_MODEL, threads)
        self._det_in = self._det.get_input_details()[0]["index"]
        outs = {d["name"]: d["index"] for d in self._det.get_output_details()}
        self._det_boxes, self._det_scores = outs["regressors"], outs["classificators"]
        self._mesh_in = self._mesh.get_input_details()[0]["index"]
        outs = sorted(self._mesh.get_output_details(), key=lambda d: -int(np.prod(d["shape"])))
        self._mesh_points, self._mesh_score = outs[0]["index"], outs[1]["index"]
        self._det_buf = np.zeros((1, DETECTOR_SIZE, DETECTOR_SIZE, 3), np.float32)
        self._mesh_buf = np.zeros((1, MESH_SIZE, MESH_SIZE, 3), np.float32)
        self._crop = np.zeros((MESH_SIZE, MESH_SIZE, 3), np.uint8)

    def detect(self, image: np.ndarray) -> List[Detection]:
        """Every face in ``image`` (RGB ``uint8``), largest first.

        Parameters
        ----------
        image : numpy.ndarray
            ``(H, W, 3)`` RGB (an alpha channel is ignored).

        Returns
        -------
        list of Detection
        """
        h, w = image.shape[:2]
        scale = DETECTOR_SIZE / max(h, w)
        nw, nh = max(1, round(w * scale)), max(1, round(h * scale))
        px, py = (DETECTOR_SIZE - nw) // 2, (DETECTOR_SIZE - nh) // 2
        small = cv2.resize(image[:, :, :3], (nw, nh), interpolation=cv2.INTER_AREA)
        buf = self._det_buf
        buf.fill(-1.0)  # letterbox padding is black, as MediaPipe's image-to-tensor pads
        np.multiply(small, 1 / 127.5, out=buf[0, py:py + nh, px:px + nw], casting="unsafe")
        buf[0, py:py + nh, px:px + nw] -= 1.0
        self._det.set_tensor(self._det_in, buf)
        self._det.invoke()
        raw = _decode_detections(self._det.get_tensor(self._det_boxes), self._det.get_tensor(self._det_scores))
        out = []
        for box, kps, score in raw:
            # Normalised letterboxed input → image pixels (edges at 0) → pixel centres.
            def back(p):
                return (p * DETECTOR_SIZE - np.array([px, py])) / scale - 0.5
            out.append(Detection(np.concatenate([back(box[:2]), back(box[2:])]), back(kps), score))
        out.sort(key=lambda d: -d.area)
        return out

    def landmarks_in(self, image: np.ndarray, roi: Roi) -> Tuple[np.ndarray, float]:
        """The mesh's 468 points for the face inside ``roi``.

        Returns
        -------
        points : numpy.ndarray
            float64 ``(468, 3)``: x, y in image pixels, z in the same scale.
        score : float
            Face presence, 0–1 (below :data:`MIN_MESH_SCORE` the ROI holds no face).
        """
        m = roi.crop_matrix(MESH_SIZE)
        cv2.warpAffine(image[:, :, :3] if image.shape[2] != 3 else image, m, (MESH_SIZE, MESH_SIZE),
                       dst=self._crop, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                       borderMode=cv2.BORDER_REPLICATE)
        np.multiply(self._crop, 1 / 255.0, out=self._mesh_buf[0], casting="unsafe")
        self._mesh.set_tensor(self._mesh_in, self._mesh_buf)
        self._mesh.invoke()
        raw = self._mesh.get_tensor(self._mesh_points).reshape(468, 3).astype(np.float64)
        logit = float(np.clip(self._mesh.get_tensor(self._mesh_score).reshape(-1)[0], -_SCORE_CLIP, _SCORE_CLIP))
        return roi.to_image(raw), 1.0 / (1.0 + math.exp(-logit))

    def find(self, image: np.ndarray, *, source: Optional[str] = None, refine: int = 1) -> np.ndarray:
        """The 468 mesh points of the largest face in a still picture.

        The mesh runs on the detector's region, then again ``refine`` times on the region its
        own points give (the tracking region, which fits the face more tightly).

        Parameters
        ----------
        image : numpy.ndarray
            RGB ``uint8`` ``(H, W, 3)``.
        source : str, optional
            The picture's name for messages ("photo.png", "clip.mp4 frame 12").
        refine : int
            Extra mesh passes on the landmark-derived region.

        Returns
        -------
        numpy.ndarray
            float64 ``(468, 3)``.

        Raises
        ------
        NoFaceError
            No face in the picture. Several faces give a :class:`FaceWarning` and the largest.
        """
        dets = self.detect(image)
        if not dets:
            raise NoFaceError("no face found", path=source)
        if len(dets) > 1:
            warnings.warn(f"{source or 'picture'}: {len(dets)} faces found; using the largest",
                          FaceWarning, stacklevel=2)
        points, score = self.landmarks_in(image, Roi.from_detection(dets[0]))
        for _ in range(refine):
            again, again_score = self.landmarks_in(image, Roi.from_landmarks(points))
            if again_score >= MIN_MESH_SCORE:
                points, score = again, again_score
        if score < MIN_MESH_SCORE:
            raise NoFaceError(f"a face was detected but the mesh could not place it (score {score:.2f})",
                              path=source)
        return points
