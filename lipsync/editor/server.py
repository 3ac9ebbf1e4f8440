"""The ``lipsync edit`` server: the page, the bank's images, drafts, previews and save.

API (every ``/api/`` call needs the session token, see :mod:`lipsync.web`):

``GET /api/bank``
    ``{doc, header, shape: [H, W], axis, version, path}``: the bank document as plain data
    (the YAML as ``yaml.safe_load`` reads it, key order kept).
``GET /api/image/{name}``
    An image file of the bank folder (PNG/JPEG only; nothing outside the folder).
``POST /api/draft`` with ``{doc}``
    Validates the edited document with the real loader (:meth:`lipsync.banks.bank.Bank.from_text`);
    valid → it becomes the draft the preview shows and its missing flows are queued for the
    background worker: ``{ok: true, version}``; invalid → 422 ``{ok: false, error}`` where
    ``error`` has ``message``, ``viseme``, ``feature``, ``line``.
``GET /api/preview?from=A&to=D&alpha=0.5``
    PNG of the draft's in-between frame from :class:`lipsync.morphing.render.Renderer`: the ``flow``
    method when the pair's flows for the draft are in the store, ``beier-neely`` (exact, no
    flows needed) meanwhile. Headers ``X-Lipsync-Method``, ``X-Lipsync-Version``.
``GET /api/status``
    ``{version, flows: {done, total, computing}, ready: [[A, B], ...]}``.
``POST /api/save`` with ``{doc}``
    Validates like a draft; valid → bank.yaml written atomically (top comments kept), also
    made the draft; invalid → 422 and nothing written. No other file can be written.

Flows go to the bank's own store (``BANK/.lipsync``, or ``--store``), the one ``lipsync
render`` reads, so a saved bank's flows are already there; :meth:`Editor.close` removes the
entries the editor wrote that the bank as saved does not use (abandoned drafts). A save is
refused with 409 when bank.yaml changed on disk since the editor read or wrote it.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np
import yaml

from .. import _yaml
from ..banks.bank import Bank
from ..banks.yamlio import dump_bank, header_comments, write_bank_text
from ..errors import BankError, InputError
from ..morphing.normalise import normalise
from ..morphing.preprocess import all_pairs
from ..morphing.render import Renderer
from ..morphing.store import FlowStore
from ..web import Guard, PathRefused, Session, resolve_inside

STATIC = Path(__file__).resolve().parent / "static"
#: Files the page may load from the bank folder.
IMAGE_TYPES = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp",
               ".bmp": "image/bmp"}
#: A bank.yaml is at most 1 MiB (bank.MAX_YAML_BYTES); its JSON form is about as large.
MAX_BODY = 2 << 20
#: Drafts kept renderable at once: the current one and the one before it (a preview request
#: may still name it).
KEEP_DRAFTS = 2
#: How long a preview waits for the flows of its pair before rendering with Beier-Neely:
#: a pair of a symmetric 512x512, 41-line bank takes ~0.3 s idle, ~1 s on a busy machine (make
#: bench, figure "editor"), and a Beier-Neely frame costs more than that.
PREVIEW_WAIT_S = 1.0


@dataclass(frozen=True)
class _DigestedBank(Bank):
    """A bank whose image digests were computed once per image file (the editor's images
    never change, and hashing all of them for every draft's store keys costs ~0.1 s)."""

    digests: Dict[str, str] = field(default_factory=dict, repr=False, compare=False)

    def image_digest(self, viseme: str) -> str:
        return self.digests[viseme]


class _Draft:
    """One validated state of the edited bank and its renderers (built on first use)."""

    def __init__(self, version: int, bank: Bank, store: FlowStore):
        self.version = version
        self.bank = bank
        self.store = store
        # Reentrant: render() holds it while the normalised bank is built on first use.
        self.lock = threading.RLock()
        self._nb = None
        self._renderers: Dict[str, Renderer] = {}
        self._keys: Dict[Tuple[str, str], str] = {}

    @property
    def nb(self):
        with self.lock:
            if self._nb is None:
                self._nb = normalise(self.bank, cache=self.store)
            return self._nb

    def pair_key(self, a: str, b: str) -> str:
        """Store key of the pair (in bank order); memoised, as it hashes both images."""
        names = self.bank.names
        pair = (a, b) if names.index(a) <= names.index(b) else (b, a)
        key = self._keys.get(pair)
        if key is None:
            key = self._keys[pair] = self.store.pair_key(self.bank, pair[0], pair[1], self.nb.axis)
        return key

    def pair_ready(self, a: str, b: str) -> bool:
        return self.store.pair_path(self.pair_key(a, b)).exists()

    def render(self, a: str, b: str, alpha: float) -> Tuple[np.ndarray, str]:
        with self.lock:
            method = "flow" if a == b or self.pair_ready(a, b) else "beier-neely"
            r = self._renderers.get(method)
            if r is None:
                r = self._renderers[method] = Renderer(self.nb, method=method, store=self.store)
            return r.render(a, b, alpha).copy(), method


class FlowWorker:
    """Computes the flows a draft lacks, one pair at a time, newest draft first.

    A new draft replaces the queue; the pair being shown goes to its front.
    """

    def __init__(self):
        self._cond = threading.Condition()
        self._draft: Optional[_Draft] = None
        self._todo: List[Tuple[str, str]] = []
        self.total = 0
        self.done = 0
        self.computing: Optional[Tuple[str, str]] = None
        self.written: set = set()  # store keys this worker wrote (drafts' flows)
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="lipsync-edit-flows", daemon=True)
        self._thread.start()

    def submit(self, draft: _Draft, first: Optional[Tuple[str, str]] = None) -> None:
        with draft.lock:
            todo = [p for p in all_pairs(draft.bank.names) if not draft.pair_ready(*p)]
        with self._cond:
            if self._draft is not None and draft.version < self._draft.version:
                return  # two requests raced: a newer draft is queued already
            self._draft, self._todo = draft, todo
            self.total, self.done = len(todo), 0
            if first:
                self._prioritise(first)
            self._cond.notify_all()

    def prioritise(self, a: str, b: str) -> None:
        with self._cond:
            self._prioritise((a, b))

    def _prioritise(self, pair) -> None:
        for p in (tuple(pair), tuple(pair)[::-1]):
            if p in self._todo:
                self._todo.remove(p)
                self._todo.insert(0, p)

    def wait_for(self, draft: _Draft, a: str, b: str, timeout: float) -> bool:
        """Wait up to ``timeout`` s while the pair (a, b) of ``draft`` is queued first or computing."""
        deadline = time.monotonic() + timeout
        pairs = {(a, b), (b, a)}
        with self._cond:
            while True:
                if draft.pair_ready(a, b):
                    return True
                busy = self._draft is draft and (self.computing in pairs or
                                                 (self._todo and self._todo[0] in pairs))
                left = deadline - time.monotonic()
                if not busy or left <= 0:
                    return False
                self._cond.wait(left)

    def status(self) -> dict:
        with self._cond:
            return {"done": self.done, "total": self.total,
                    "computing": list(self.computing) if self.computing else None}

    def stop(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()

    def join(self, timeout: float) -> None:
        """Wait for the pair being computed (if any) to finish after :meth:`stop`."""
        self._thread.join(timeout)

    def wait_idle(self, timeout: float) -> bool:
        """Block until nothing is queued or computing (tests, benchmarks)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._todo or self.computing:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
        return True

    def _run(self) -> None:
        from ..morphing.preprocess import bank_pair_flows

        while True:
            with self._cond:
                while not self._todo and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                draft = self._draft
                a, b = self._todo.pop(0)
                self.computing = (a, b)
            try:
                bank, nb = draft.bank, draft.nb
                key = draft.pair_key(a, b)
                fwd, bwd, axis = bank_pair_flows(nb, a, b)
                draft.store.put_pair(key, fwd, bwd, axis=axis, names=(a, b))
                with self._cond:
                    self.written.add(key)
            except OSError:
                pass  # an unwritable store: the preview stays on beier-neely
            with self._cond:
                self.computing = None
                if draft is self._draft:
                    self.done += 1
                self._cond.notify_all()


class Editor:
    """State of one ``lipsync edit`` run: the bank folder, its drafts and the flow worker.

    Parameters
    ----------
    bank_dir : path-like
        The bank folder (its bank.yaml must load).
    store : FlowStore, optional
        Where flows go (default: the bank's store).
    """

    def __init__(self, bank_dir, *, store: Optional[FlowStore] = None):
        bank = Bank.load(bank_dir)
        self.folder = bank.path.resolve()
        self.yaml_path = self.folder / "bank.yaml"
        text = self.yaml_path.read_text(encoding="utf-8")
        self._on_disk = text  # what we last read or wrote: a save must not clobber other edits
        self.header = header_comments(text)
        self.doc = _yaml.safe_load(text)
        self.store = store or FlowStore.for_bank(bank)
        # Decoded images by file name: validation reuses them instead of decoding per edit.
        self.images = {self.doc["visemes"][v]["image"]: bank.images[v] for v in bank.names}
        self._digests: Dict[str, str] = {}
        self._lock = threading.Lock()
        self._face_lock = threading.Lock()  # the face models are not thread-safe
        self._version = 0
        self._drafts: Dict[int, _Draft] = {}
        self.worker = FlowWorker()
        self._first = self.validate(self.doc)[1]
        self._set_draft(self._first)

    # ------------------------------------------------------------------ drafts
    def _set_draft(self, bank: Bank, first: Optional[Tuple[str, str]] = None) -> _Draft:
        with self._lock:
            self._version += 1
            draft = _Draft(self._version, bank, self.store)
            self._drafts[draft.version] = draft
            for old in sorted(self._drafts)[:-KEEP_DRAFTS]:
                del self._drafts[old]
        self.worker.submit(draft, first)
        return draft

    @property
    def draft(self) -> _Draft:
        with self._lock:
            return self._drafts[max(self._drafts)]

    def validate(self, doc) -> Tuple[str, Bank]:
        """bank.yaml text for ``doc`` and the bank it loads as; BankError/InputError if invalid."""
        if not isinstance(doc, dict):
            raise InputError("the document must be a mapping (name, rest, visemes, ...)")
        try:
            text = dump_bank(doc, header=self.header)
        except (ValueError, TypeError, RecursionError) as exc:
            raise InputError(f"cannot write this document as YAML: {exc}") from None
        bank = Bank.from_text(text, self.folder, images=self.images)
        digests = {}
        for v in bank.names:
            rel = doc["visemes"][v]["image"]
            if rel not in self._digests or self.images.get(rel) is not bank.images[v]:
                self._digests[rel] = Bank.image_digest(bank, v)
            digests[v] = self._digests[rel]
        return text, _DigestedBank(**{f.name: getattr(bank, f.name) for f in fields(Bank)}, digests=digests)

    def propose(self, doc, first: Optional[Tuple[str, str]] = None) -> _Draft:
        _, bank = self.validate(doc)
        return self._set_draft(bank, first)

    def save(self, doc) -> _Draft:
        text, bank = self.validate(doc)
        with self._lock:
            try:
                now = self.yaml_path.read_text(encoding="utf-8")
            except OSError:
                now = None
            if now != self._on_disk:
                raise ConflictError("bank.yaml was changed by someone else since the editor read it; "
                                    "nothing was written (restart lipsync edit to load that version)",
                                    path=self.yaml_path)
            write_bank_text(self.yaml_path, text)
            self._on_disk = text
            self.doc = doc
            self._saved = bank
        return self._set_draft(bank)

    def place_from_face(self, doc, visemes) -> Tuple[dict, Dict[str, str], Optional[float]]:
        """A copy of ``doc`` with lines placed from the faces in its images.

        ``visemes`` is a list of viseme names or ``"all"``. All visemes get the face template's
        lines (and its warp weights, and ``symmetry`` as the faces allow); a list replaces only
        those visemes' lines, which needs the bank to have face lines already (every viseme has
        the same line names). Returns the new document and, per viseme placed, where its lines
        came from, and the mirror axis the new lines are normalised about (None without
        symmetry). InputError when no image shows a face or the request does not fit the bank.
        """
        from ..videobank.photos import place_face_lines
        from ..face.landmarks import FaceMesh
        from ..face.lines import FACE_WARP

        _, bank = self.validate(doc)
        if visemes == "all":
            chosen = list(bank.names)
        elif isinstance(visemes, list) and visemes and all(isinstance(v, str) for v in visemes):
            unknown = [v for v in visemes if v not in bank.names]
            if unknown:
                raise InputError(f"not visemes of this bank: {', '.join(map(str, unknown))}")
            chosen = visemes
        else:
            raise InputError('"visemes" must be "all" or a list of viseme names')
        with self._lock:
            if getattr(self, "_mesh", None) is None:
                self._mesh = FaceMesh()
            mesh = self._mesh
        labels = {v: doc["visemes"][v]["image"] for v in bank.names}
        with self._face_lock:
            placed = place_face_lines(dict(bank.images), bank.rest, labels=labels, mesh=mesh)
        if placed is None:
            raise InputError("no face found in any of the bank's images (" + ", ".join(labels.values()) + ")")
        new = json.loads(json.dumps(doc))
        if visemes == "all":
            new["warp"] = {"a": FACE_WARP.a, "b": FACE_WARP.b, "p": FACE_WARP.p}
            new["symmetry"] = placed.symmetric
        else:
            ours = list(doc["visemes"][chosen[0]]["lines"])
            if ours != list(placed.features[chosen[0]]):
                raise InputError("this bank's lines are not the face template's; place them from the face on "
                                 "all visemes (its lines then become face lines everywhere)")
        for v in chosen:
            new["visemes"][v]["lines"] = {n: f.to_yaml_value() for n, f in placed.features[v].items()}
        _, checked = self.validate(new)
        return new, {v: placed.sources[v] for v in chosen}, normalise_axis(checked)

    def close(self) -> None:
        """Stop the worker and remove the flows of abandoned drafts (those it wrote that the
        last saved bank does not use); entries that were there before are left alone."""
        self.worker.stop()
        self.worker.join(30)
        saved = getattr(self, "_saved", None) or self._first
        keep = {self.store.pair_key(saved, a, b, normalise_axis(saved)) for a, b in all_pairs(saved.names)}
        for key in self.worker.written - keep:
            try:
                self.store.pair_path(key).unlink()
            except OSError:
                pass


class ConflictError(InputError):
    """bank.yaml changed on disk while the editor had it open."""


def normalise_axis(bank: Bank) -> Optional[float]:
    """The mirror axis the flows of ``bank`` are keyed with (None without symmetry)."""
    from ..morphing.normalise import bank_axis

    return bank_axis(bank) if bank.symmetry else None


def _error_json(exc: Exception) -> dict:
    return {"message": str(exc), "viseme": getattr(exc, "viseme", None),
            "feature": getattr(exc, "feature", None), "line": getattr(exc, "line", None)}


def make_app(editor: Editor, session: Session, *, max_body: int = MAX_BODY):
    """The Starlette app of the editor wrapped in :class:`lipsync.web.Guard`.

    Examples
    --------
    >>> from starlette.testclient import TestClient
    >>> from lipsync._data import default_bank_dir
    >>> import shutil, tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp()) / "toon"
    >>> _ = shutil.copytree(default_bank_dir(), d)
    >>> s = Session.open(); ed = Editor(d)
    >>> c = TestClient(make_app(ed, s), base_url=s.origin)
    >>> c.get(s.url("/api/bank")).json()["shape"]
    [512, 512]
    >>> ed.close(); s.close()
    """
    from starlette.applications import Starlette
    from starlette.responses import FileResponse, JSONResponse, Response
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    def bad(message: str, status: int = 400) -> JSONResponse:
        return JSONResponse({"ok": False, "error": {"message": message}}, status_code=status)

    async def read_doc(request):
        try:
            payload = json.loads(await request.body())
        except (ValueError, RecursionError):
            return None, bad("the request body must be JSON")
        if not isinstance(payload, dict) or not isinstance(payload.get("doc"), dict):
            return None, bad("expected {\"doc\": {...}}")
        return payload, None

    async def index(request):
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    def bank_info(request):
        d = editor.draft
        return JSONResponse({"doc": editor.doc, "header": editor.header, "shape": list(d.bank.shape),
                             "axis": d.nb.axis, "version": d.version, "path": str(editor.yaml_path),
                             "names": list(d.bank.names)})

    def image(request):
        name = request.path_params["name"]
        try:
            path = resolve_inside(editor.folder, name)
        except PathRefused as exc:
            return bad(str(exc), 404)
        kind = IMAGE_TYPES.get(path.suffix.lower())
        if kind is None or not path.is_file():
            return bad("only the bank's PNG and JPEG images can be read", 404)
        return FileResponse(path, media_type=kind)

    async def draft(request):
        payload, err = await read_doc(request)
        if err:
            return err
        first = payload.get("pair")
        first = tuple(first) if isinstance(first, list) and len(first) == 2 and all(
            isinstance(x, str) for x in first) else None
        try:
            d = await _in_thread(editor.propose, payload["doc"], first)
        except InputError as exc:
            return JSONResponse({"ok": False, "error": _error_json(exc)}, status_code=422)
        return JSONResponse({"ok": True, "version": d.version})

    async def save(request):
        payload, err = await read_doc(request)
        if err:
            return err
        try:
            d = await _in_thread(editor.save, payload["doc"])
        except ConflictError as exc:
            return JSONResponse({"ok": False, "error": _error_json(exc)}, status_code=409)
        except InputError as exc:
            return JSONResponse({"ok": False, "error": _error_json(exc)}, status_code=422)
        return JSONResponse({"ok": True, "version": d.version, "path": str(editor.yaml_path)})

    async def face(request):
        payload, err = await read_doc(request)
        if err:
            return err
        try:
            doc, sources, axis = await _in_thread(editor.place_from_face, payload["doc"],
                                                  payload.get("visemes", "all"))
        except InputError as exc:
            return JSONResponse({"ok": False, "error": _error_json(exc)}, status_code=422)
        return JSONResponse({"ok": True, "doc": doc, "sources": sources, "axis": axis})

    def preview(request):
        q = request.query_params
        d = editor.draft
        a, b = q.get("from", ""), q.get("to", "")
        if a not in d.bank.names or b not in d.bank.names:
            return bad(f"from and to must be visemes of the bank ({', '.join(d.bank.names)})")
        try:
            alpha = float(q.get("alpha", "0.5"))
        except ValueError:
            return bad("alpha must be a number")
        if not 0.0 <= alpha <= 1.0:
            return bad("alpha must be between 0 and 1")
        if a != b and not d.pair_ready(a, b):
            editor.worker.prioritise(a, b)
            # The shown pair's flows take ~0.3 s for a 512x512 bank, less than a Beier-Neely
            # frame; wait that long for them before falling back to Beier-Neely.
            editor.worker.wait_for(d, a, b, PREVIEW_WAIT_S)
        frame, method = d.render(a, b, alpha)
        import cv2

        to_bgr = cv2.COLOR_RGBA2BGRA if frame.shape[2] == 4 else cv2.COLOR_RGB2BGR  # PNG keeps alpha
        ok, png = cv2.imencode(".png", cv2.cvtColor(frame, to_bgr), [cv2.IMWRITE_PNG_COMPRESSION, 1])
        return Response(png.tobytes(), media_type="image/png",
                        headers={"X-Lipsync-Method": method, "X-Lipsync-Version": str(d.version),
                                 "Cache-Control": "no-store"})

    def status(request):
        d = editor.draft
        with d.lock:
            ready = [[a, b] for a, b in all_pairs(d.bank.names) if d.pair_ready(a, b)]
        return JSONResponse({"version": d.version, "flows": editor.worker.status(), "ready": ready})

    routes = [
        Route("/", index),
        Route("/index.html", index),
        Route("/api/bank", bank_info),
        Route("/api/image/{name:path}", image),
        Route("/api/draft", draft, methods=["POST"]),
        Route("/api/save", save, methods=["POST"]),
        Route("/api/face", face, methods=["POST"]),
        Route("/api/preview", preview),
        Route("/api/status", status),
        Mount("/static", app=StaticFiles(directory=STATIC)),
    ]
    return Guard(Starlette(routes=routes), session=session, max_body=max_body)


async def _in_thread(fn, *args):
    from starlette.concurrency import run_in_threadpool

    return await run_in_threadpool(fn, *args)
