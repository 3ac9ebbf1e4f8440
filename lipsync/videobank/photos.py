"""A starting bank.yaml for a folder of viseme images (``lipsync init``).

One viseme per image, named from the file name (:mod:`.names`); every image must have one
size. The control lines come from a template bank (the shipped toon by default): each new
viseme gets the lines of the template viseme with the same mouth shape, moved onto the
image by a scale and a shift, so that the first morph already looks like a mouth opening
and the editor (``lipsync edit``) only has to nudge lines onto the drawing.

Two layouts:

* ``face`` — a whole face (photo or drawing): the template's face and mouth lines are
  scaled to the image (uniformly, centred), or mapped onto ``face_box`` when given; the
  template's frame lines (``frame_*``, which pin the picture's border) follow the border.
* ``mouth`` — a mouth-only sprite, as Rhubarb users draw them: there are no eyes or chin to
  anchor, so only the template's mouth lines are kept, plus the frame lines that keep the
  sprite's border still. The mouth lines go where the sprites differ from one another (the
  box of pixels that change between visemes: that is where the mouth moves), the template's
  mouth box fitted into it; when nothing differs enough they fill :data:`MOUTH_FILL` of the
  sprite around its centre.

``auto`` (the default) picks ``mouth`` for images of at most :data:`SPRITE_MAX_SIDE`
pixels a side without a face box, ``face`` otherwise.

Mouth sprites are drawn to sit on a character: ``composite`` (``lipsync init DIR --over
BODY --at X,Y [--scale S]``) writes the bank's ``composite:`` block, so that ``lipsync
render`` shows the whole character talking (:mod:`lipsync.composite`); the body image is
not a viseme.

Where the lines come from (``lines``):

* ``face`` — each image's own face: the face mesh (:mod:`lipsync.face`) is placed on every
  image and :func:`lipsync.face.lines.face_features` turns it into lines on the lips, jaw,
  eyes, brows, nose and the still parts of the face, so a photo of a face needs no hand
  work. An image in which no face is found borrows the lines of the rest viseme's face (or
  the first image with one), and the result says so: the editor's "Place from face" or a
  drag puts them right. The bank gets ``symmetry: true`` only when the faces are symmetric
  (:data:`lipsync.face.lines.SYMMETRIC_BELOW`): normalising a real face that is turned or
  tilted would visibly change it.
* ``template`` — the template bank's lines moved onto the images (the layouts above).
* ``auto`` (the default) — ``face`` when a face is found in at least one image of the face
  layout, else ``template`` (drawings without a recognisable face, mouth sprites).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..banks.bank import Bank, Feature, _read_image
from ..errors import InputError
from ..registry import Registry
from ..banks.names import IMAGE_SUFFIXES, REST, SYSTEMS, name_images
from ..banks.yamlio import dump_bank, write_bank_text

#: Template banks by name; ``--template`` also takes a bank folder.
TEMPLATES: Registry = Registry("template")


def _toon_dir() -> Path:
    from .._data import default_bank_dir

    return default_bank_dir()


TEMPLATES.register("toon", _toon_dir)

LAYOUTS = ("auto", "face", "mouth")
#: Where the control lines come from (see the module docstring).
LINE_SOURCES = ("auto", "face", "template")
#: Rhubarb-style mouth sprites are ~100-250 px; a face that shows eyes, nose and mouth
#: clearly enough to place lines on is larger.
SPRITE_MAX_SIDE = 256
#: Share of a sprite's width or height the template's widest mouth fills (room for lips
#: that open further than the template's).
MOUTH_FILL = 0.8
#: A pixel "moves" when its value spans more than this across the visemes (0-255): above
#: JPEG noise and anti-aliasing wobble, below any real change of lip or teeth.
MOVING_LEVEL = 24
#: Fewer moving pixels than this share of the sprite: no usable mouth region.
MOVING_MIN_SHARE = 0.002
#: Line names that belong to the mouth (kept in the mouth layout), by prefix.
MOUTH_PREFIXES = ("upper_", "lower_", "corner_", "teeth_", "lip", "mouth", "tongue")
#: Lines that pin the picture's border: scaled with the image, not the face.
FRAME_PREFIX = "frame_"


@dataclass(frozen=True)
class InitResult:
    """What :func:`init_bank` wrote."""

    yaml_path: Path
    visemes: Dict[str, str]  # viseme -> image file name
    system: Optional[str]
    rest: str
    layout: str
    size: Tuple[int, int]  # (W, H)
    #: viseme -> where its lines came from: "face", "template <name>", or "face of <image>
    #: (no face found in <image>)" for an image that borrowed another's face.
    lines: Dict[str, str] = field(default_factory=dict)
    #: Whether the pictures are one face (written to :data:`ONE_FACE_DIR`; ``keep_photos``
    #: off and faces found).
    one_face: bool = False


def _images(folder: Path, exclude: Sequence[str] = ()) -> List[Path]:
    files = sorted(p for p in folder.iterdir()
                   if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith(".")
                   and p.name not in exclude)
    if not files:
        raise InputError("no PNG or JPEG images here (one image per viseme)", path=folder)
    return files


def _affine(points: np.ndarray, scale: Tuple[float, float], origin_from, origin_to) -> np.ndarray:
    return (points - np.asarray(origin_from)) * np.asarray(scale) + np.asarray(origin_to)


def _bbox(features: Sequence[Dict[str, Feature]], keep) -> np.ndarray:
    pts = np.concatenate([f.points for fs in features for n, f in fs.items() if keep(n)])
    return np.array([pts.min(axis=0), pts.max(axis=0)])


def _moving_box(images) -> Optional[np.ndarray]:
    """``[[x0, y0], [x1, y1]]`` (pixel centres) of the pixels that change between images."""
    stack = np.stack(list(images))
    if stack.shape[-1] == 4:  # sprites: compare what shows (premultiplied), not hidden colours
        stack = (stack[..., :3].astype(np.uint16) * stack[..., 3:] // 255).astype(np.uint8)
    span = (stack.max(axis=0).astype(np.int16) - stack.min(axis=0)).max(axis=2)
    ys, xs = np.nonzero(span > MOVING_LEVEL)
    if xs.size < MOVING_MIN_SHARE * span.size:
        return None
    return np.array([[xs.min(), ys.min()], [xs.max(), ys.max()]], dtype=np.float64)


def _is_mouth(name: str) -> bool:
    return name.startswith(MOUTH_PREFIXES)


def _with_composite(doc: dict, composite: dict) -> dict:
    """``doc`` with a ``composite:`` block just before ``visemes:``."""
    block = {"image": composite["image"], "at": [float(v) for v in composite["at"]],
             "scale": float(composite.get("scale", 1.0))}
    out = {k: v for k, v in doc.items() if k != "visemes"}
    out["composite"] = block
    out["visemes"] = doc["visemes"]
    return out


def parse_face_box(text: str) -> Tuple[float, float, float, float]:
    """``X,Y,W,H`` → floats; width and height must be positive.

    Examples
    --------
    >>> parse_face_box("10, 20, 300, 400")
    (10.0, 20.0, 300.0, 400.0)
    """
    try:
        x, y, w, h = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"--face-box: expected X,Y,W,H in pixels, got {text!r}") from None
    if not (w > 0 and h > 0) or not all(np.isfinite([x, y, w, h])):
        raise InputError(f"--face-box: width and height must be positive, got {text!r}")
    return x, y, w, h


def init_bank(folder, *, template: str = "toon", names: Optional[Dict[str, str]] = None,
              face_box: Optional[Tuple[float, float, float, float]] = None, layout: str = "auto",
              rest: Optional[str] = None, force: bool = False, lines: str = "auto",
              composite: Optional[dict] = None, keep_photos: bool = False) -> InitResult:
    """Write ``folder/bank.yaml`` for the images in ``folder``; it passes ``lipsync check``.

    Parameters
    ----------
    folder : path-like
        A folder of PNG/JPEG images, one per viseme.
    template : str
        A template name (``toon``) or a bank folder whose lines to start from.
    names : dict, optional
        File stem → viseme name, for files whose names are not a known viseme name.
    face_box : (x, y, w, h), optional
        Where the face is in the images; the template's face is mapped onto it.
    layout : {"auto", "face", "mouth"}
        See the module docstring.
    rest : str, optional
        The rest viseme (default: X, rest or sil, whichever the names give).
    force : bool
        Overwrite an existing bank.yaml.
    lines : {"auto", "face", "template"}
        Where the control lines come from (see the module docstring).
    composite : dict, optional
        ``{"image": NAME, "at": [x, y], "scale": s}``: the body image (a file in ``folder``,
        not a viseme) the mouth is drawn on and where, written as the bank's ``composite:``.
    keep_photos : bool
        With lines from the faces, the bank's pictures are by default *one face*: the rest
        image (the plate) everywhere except the lower face, where each image's mouth, jaw
        and chin, moved onto the plate's pose, are pasted in (:data:`ONE_FACE_DIR`, see
        :func:`lipsync.composite.face.onto_plate`); ``keep_photos`` uses the images as they
        are.

    Returns
    -------
    InitResult

    Raises
    ------
    InputError
        No images, unrecognised names, images of differing sizes, an existing bank.yaml
        without ``force``, a face box outside the images, ``lines="face"`` and no face in
        any image.

    Examples
    --------
    >>> import tempfile, shutil
    >>> from pathlib import Path
    >>> from lipsync._data import default_bank_dir
    >>> d = Path(tempfile.mkdtemp())
    >>> for v in "AX": _ = shutil.copy(default_bank_dir() / f"{v}.png", d / f"mouth_{v}.png")
    >>> r = init_bank(d)
    >>> r.rest, r.layout, sorted(Bank.load(d).names)
    ('X', 'face', ['A', 'X'])
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("not a folder (give the folder that holds the viseme images)", path=folder)
    if layout not in LAYOUTS:
        raise InputError(f"unknown layout {layout!r}; one of: {', '.join(LAYOUTS)}")
    if lines not in LINE_SOURCES:
        raise InputError(f"unknown line source {lines!r}; one of: {', '.join(LINE_SOURCES)}")
    yaml_path = folder / "bank.yaml"
    if yaml_path.exists() and not force:
        raise InputError("bank.yaml exists already; use --force to replace it", path=yaml_path)

    body_name = composite["image"] if composite else None
    named, system = name_images(_images(folder, exclude=[body_name] if body_name else []), names)
    images = {}
    size = None
    first = None
    for v, path in named.items():
        img = _read_image(path, f"viseme {v!r}", path, None)
        if size is None:
            size, first = img.shape[:2], path
        elif img.shape[:2] != size:
            raise InputError(f"image is {img.shape[1]}x{img.shape[0]} but {first.name} is {size[1]}x{size[0]}; "
                             f"all visemes need one size", path=path)
        images[path.name] = img
    h, w = size
    if any(img.shape[2] == 4 for img in images.values()):  # one layout, as the bank loader makes it
        import cv2

        images = {n: img if img.shape[2] == 4 else cv2.cvtColor(img, cv2.COLOR_RGB2RGBA) for n, img in images.items()}
    cache = dict(images)  # what Bank.from_text may take as decoded (the viseme images, the body)
    if composite:
        # the body is validated with the bank (Bank.from_text): inside the folder, placement in range
        cache[body_name] = _read_image(folder / body_name, "composite", folder / body_name, None)

    # Viseme order: the naming system's, then others by name.
    order = list(SYSTEMS[system]) if system else []
    visemes = [v for v in order if v in named] + sorted(v for v in named if v not in order)
    shape_of = {}  # viseme -> template viseme
    for v in visemes:
        shape_of[v] = next((SYSTEMS[s][v] for s in SYSTEMS if v in SYSTEMS[s]), None)
    if rest is None:
        rest = next((v for v in visemes if system and v == REST[system]), None)
        rest = rest or next((v for v in visemes if shape_of[v] == "X"), None) or visemes[0]
    elif rest not in named:
        raise InputError(f"--rest {rest!r} is not among the visemes ({', '.join(visemes)})")

    if layout == "auto":
        layout = "mouth" if face_box is None and max(h, w) <= SPRITE_MAX_SIDE else "face"
    if lines == "face" or (lines == "auto" and layout == "face"):
        faced = _face_lines(folder, named, visemes, rest, images, forced=lines == "face", one_face=not keep_photos)
        if faced is not None:
            doc, sources, symmetric, pasted = faced
            if composite:
                doc = _with_composite(doc, composite)
            header = [f"# Written by lipsync init: lines placed from each image's face "
                      f"({'symmetric' if symmetric else 'not symmetric enough for symmetry: true'}); "
                      f"adjust them with: lipsync edit {folder}"]
            if pasted:
                header.append(f"# One face: the pictures in {ONE_FACE_DIR}/ are {named[rest].name} outside the lower "
                              f"face (lipsync init --keep-photos uses the photos as they are)")
            text = dump_bank(doc, header=header)
            cache.update({f"{ONE_FACE_DIR}/{n}": img for n, img in pasted.items()})
            Bank.from_text(text, folder, images=cache)
            if pasted:
                _write_one_face(folder, pasted)
            write_bank_text(yaml_path, text)
            return InitResult(yaml_path=yaml_path, visemes={v: named[v].name for v in visemes}, system=system,
                              rest=rest, layout="face", size=(w, h), lines=sources, one_face=bool(pasted))

    if template in TEMPLATES:
        tdir = Path(TEMPLATES.get(template)())
    elif Path(template, "bank.yaml").is_file():
        tdir = Path(template)
    else:
        TEMPLATES.get(template)  # raises, listing the template names

    tbank = Bank.load(tdir)
    th, tw = tbank.shape
    default_shape = tbank.rest
    tfeatures = [tbank.features[v] for v in tbank.names]
    if layout == "mouth":
        keep = _is_mouth
        box = _bbox(tfeatures, _is_mouth)
        centre_from = box.mean(axis=0)
        extent = np.maximum(box[1] - box[0], 1e-6)
        moving = _moving_box(images.values()) if len(images) > 1 else None
        if moving is not None:
            size = np.maximum(moving[1] - moving[0], 1.0)
            s = min(size[0] / extent[0], size[1] / extent[1])
            scale, origin_from, origin_to = (s, s), centre_from, tuple(moving.mean(axis=0))
        else:
            s = MOUTH_FILL * min(w / extent[0], h / extent[1])
            scale, origin_from, origin_to = (s, s), centre_from, ((w - 1) / 2, (h - 1) / 2)
    else:
        def keep(n):
            return True
        if face_box is not None:
            bx, by, bw, bh = face_box
            if bx < 0 or by < 0 or bx + bw > w or by + bh > h:
                raise InputError(f"--face-box {bx:g},{by:g},{bw:g},{bh:g} reaches outside the {w}x{h} images")
            box = _bbox(tfeatures, lambda n: not n.startswith(FRAME_PREFIX))
            extent = np.maximum(box[1] - box[0], 1e-6)
            scale, origin_from, origin_to = (bw / extent[0], bh / extent[1]), box[0], (bx, by)
        else:
            # Pixel centres: template column x covers [x - 0.5, x + 0.5], so the scale acts on
            # x + 0.5; the template is centred in the image.
            s = min(w / tw, h / th)
            scale = (s, s)
            origin_from = (-0.5, -0.5)
            origin_to = ((w - s * tw) / 2 - 0.5, (h - s * th) / 2 - 0.5)
    frame_scale = (w / tw, h / th)

    doc_visemes = {}
    for v in visemes:
        source = tbank.features[shape_of[v] if shape_of[v] in tbank.features else default_shape]
        lines = {}
        for n, f in source.items():
            if n.startswith(FRAME_PREFIX):
                pts = _affine(f.points, frame_scale, (-0.5, -0.5), (-0.5, -0.5))
            elif keep(n):
                pts = _affine(f.points, scale, origin_from, origin_to)
            else:
                continue
            lines[n] = Feature(f.kind, pts, f.segments).to_yaml_value()
        doc_visemes[v] = {"image": named[v].name, "lines": lines}
    doc = {"name": folder.resolve().name, "rest": rest,
           "warp": {"a": tbank.warp.a, "b": tbank.warp.b, "p": tbank.warp.p},
           "symmetry": tbank.symmetry, "visemes": doc_visemes}
    if composite:
        doc = _with_composite(doc, composite)
    header = [f"# Written by lipsync init from template {template!r} ({layout} layout); "
              f"adjust the lines with: lipsync edit {folder}"]
    text = dump_bank(doc, header=header)
    Bank.from_text(text, folder, images=cache)  # refuse to write a bank that would not load
    write_bank_text(yaml_path, text)
    return InitResult(yaml_path=yaml_path, visemes={v: named[v].name for v in visemes}, system=system,
                      rest=rest, layout=layout, size=(w, h),
                      lines={v: f"template {template}" for v in visemes})


@dataclass(frozen=True)
class FacePlacement:
    """Face lines placed on a bank's images (:func:`place_face_lines`).

    Attributes
    ----------
    features : dict
        Viseme → {feature name → :class:`~lipsync.banks.bank.Feature`}, the same names on every viseme.
    sources : dict
        Viseme → ``"face"``, or ``"face of <donor> (no face found in <image>)"``.
    symmetric : bool
        Whether the faces are symmetric enough for ``symmetry: true``.
    """

    features: Dict[str, Dict[str, Feature]]
    sources: Dict[str, str]
    symmetric: bool
    #: Viseme → the face mesh found in its image (visemes without a face left out).
    found: Dict[str, np.ndarray] = field(default_factory=dict)


def place_face_lines(images: Dict[str, np.ndarray], rest: str, *, labels: Optional[Dict[str, str]] = None,
                     mesh=None) -> Optional[FacePlacement]:
    """Control lines from the face in each image; None when no image shows a face.

    An image without a face borrows the face of the rest viseme (or of the first image with
    one), so that every viseme has the same lines; :attr:`FacePlacement.sources` says which.

    Parameters
    ----------
    images : dict
        Viseme → RGB ``uint8`` image (all one size).
    rest : str
        The rest viseme (the preferred donor).
    labels : dict, optional
        Viseme → what to call its image in ``sources`` (default: the viseme's name).
    mesh : lipsync.face.landmarks.FaceMesh, optional
        Loaded models to reuse.

    Returns
    -------
    FacePlacement or None

    Examples
    --------
    >>> import numpy as np
    >>> place_face_lines({"X": np.zeros((64, 64, 3), np.uint8)}, "X") is None
    True
    """
    import warnings

    from ..face.landmarks import FaceMesh, FaceWarning, NoFaceError
    from ..face.lines import SYMMETRIC_BELOW, TURNED_ABOVE, face_asymmetry, face_features, midline_axis

    mesh = mesh or FaceMesh()
    labels = labels or {v: v for v in images}
    found: Dict[str, np.ndarray] = {}
    for v, img in images.items():
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", FaceWarning)
            try:
                found[v] = mesh.find(img, source=labels[v])
            except NoFaceError:
                continue
        for w in caught:
            warnings.warn(str(w.message), FaceWarning, stacklevel=2)
    if not found:
        return None
    turned = [labels[v] for v, p in found.items() if face_asymmetry([p]) > TURNED_ABOVE]
    if turned:
        warnings.warn(f"{', '.join(turned)}: the face is turned away from the camera; lines placed on it "
                      "will be poor on the far side (a frontal view works best)", FaceWarning, stacklevel=2)
    donor = rest if rest in found else next(v for v in images if v in found)
    points = {v: found.get(v, found[donor]) for v in images}
    sources = {v: "face" if v in found else f"face of {labels[donor]} (no face found in {labels[v]})"
               for v in images}
    symmetric = face_asymmetry(list(found.values())) < SYMMETRIC_BELOW
    axis = midline_axis(list(found.values())) if symmetric else None
    h, w = next(iter(images.values())).shape[:2]
    return FacePlacement(face_features(points, (h, w), axis=axis), sources, symmetric, found)


def _face_lines(folder: Path, named: Dict[str, Path], visemes: List[str], rest: str,
                images: Dict[str, np.ndarray], *, forced: bool, one_face: bool = False):
    """The bank document with face lines and the one-face pictures (file name → image;
    empty when the photos are kept), or None when no image has a face (and not forced)."""
    from ..face.lines import FACE_WARP

    placed = place_face_lines({v: images[named[v].name] for v in visemes}, rest,
                              labels={v: named[v].name for v in visemes})
    if placed is None:
        if forced:
            raise InputError("no face found in any image (" + ", ".join(named[v].name for v in visemes)
                             + "); --lines template starts from the template's lines instead", path=folder)
        return None
    features, files, pasted = placed.features, {v: named[v].name for v in visemes}, {}
    if one_face and rest in placed.found and len(placed.found) > 1:
        features, pictures = _one_face({v: images[named[v].name] for v in visemes}, rest, placed)
        for v, img in pictures.items():
            name = Path(named[v].name).with_suffix(".png").name
            files[v] = f"{ONE_FACE_DIR}/{name}"
            pasted[name] = img
    doc = {"name": folder.resolve().name, "rest": rest,
           "warp": {"a": FACE_WARP.a, "b": FACE_WARP.b, "p": FACE_WARP.p}, "symmetry": placed.symmetric,
           "visemes": {v: {"image": files[v],
                           "lines": {n: f.to_yaml_value() for n, f in features[v].items()}}
                       for v in visemes}}
    return doc, placed.sources, placed.symmetric, pasted


#: Where ``lipsync init`` writes the one-face pictures, inside the images' folder (bank.yaml
#: names only files inside its folder; the photos themselves are never changed).
ONE_FACE_DIR = "one-face"


def _one_face(images: Dict[str, np.ndarray], rest: str, placed: FacePlacement):
    """Every image with a face turned into the rest image (the plate) outside its lower
    face: its mouth, jaw and chin moved onto the plate's pose (one similarity, by the points
    around the mask's upper edge) and pasted in; the lines from the pasted faces. Images
    without a face keep their picture and borrowed lines."""
    import cv2

    from ..composite.face import onto_plate, pose_onto
    from ..face.lines import face_features, midline_axis

    plate, plate_points = images[rest], placed.found[rest]
    h, w = plate.shape[:2]
    pictures, points = {rest: plate}, {rest: plate_points}
    for v, p in placed.found.items():
        if v == rest:
            continue
        m = pose_onto(p, plate_points)
        warped = cv2.warpAffine(np.ascontiguousarray(images[v]), m, (w, h), flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_REPLICATE)
        moved = np.asarray(p, np.float64)[:, :2] @ m[:, :2].T + m[:, 2]
        got = onto_plate(plate, np.asarray(plate_points, np.float64)[:, :2], warped, moved)
        pictures[v], points[v] = got.image, got.points
    if len(points) < len(images):   # images without a face: the lines they borrowed
        donor = points[rest]
        points.update({v: donor for v in images if v not in points})
    axis = midline_axis(list(points.values())) if placed.symmetric else None
    features = face_features(points, (h, w), axis=axis)
    return {v: features[v] for v in images}, pictures


def _write_one_face(folder: Path, pictures: Dict[str, np.ndarray]) -> None:
    """The pictures written into ``folder/ONE_FACE_DIR`` all at once: a hidden staging
    folder renamed into place (what was there before is replaced)."""
    import shutil
    import tempfile

    import cv2

    from .._files import partial_name, remove_stale_partials

    target = folder / ONE_FACE_DIR
    remove_stale_partials(target)   # a killed run's staging folder
    stage = Path(tempfile.mkdtemp(prefix=partial_name(target, "-"), dir=folder))
    try:
        for name, img in pictures.items():
            code = cv2.COLOR_RGBA2BGRA if img.shape[-1] == 4 else cv2.COLOR_RGB2BGR
            if not cv2.imwrite(str(stage / name), cv2.cvtColor(np.ascontiguousarray(img), code)):
                raise InputError("could not write the one-face picture", path=target / name)
        if target.exists():
            shutil.rmtree(target)
        os.replace(stage, target)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
