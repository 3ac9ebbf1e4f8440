"""Banks travel by content: packed on the client, unpacked once per worker machine.

A :class:`BankPack` is the bank's ``bank.yaml`` and the image files it names (nothing else
from the folder: no flow store, no stray files), as ``(relative path, bytes)`` pairs, and
their sha256 ``digest``. The toon packs to 0.76 MB, its decoded pixels would be 7 MB.

On a worker, :func:`local_bank` unpacks a pack into ``<cache>/banks/<digest>`` (a
temporary folder renamed into place, so concurrent workers on one machine agree and a
killed worker leaves no half bank), checks the files against the digest once per process
(a damaged folder is unpacked again), loads the :class:`~lipsync.banks.bank.Bank` once per
process and keeps it, with the machine's shared :class:`~lipsync.morphing.store.FlowStore` at
``<cache>/store`` (flow keys are content hashes, so one store serves every bank).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Dict, Optional, Set, Tuple

#: Banks kept loaded per worker process (each is its decoded images: 7 MB for the toon).
MAX_LOADED_BANKS = 8


@dataclass(frozen=True)
class BankPack:
    """A bank's files by content.

    Attributes
    ----------
    digest : str
        sha256 over the sorted ``(path, bytes)`` pairs.
    name : str
        The bank's name (for messages).
    names : tuple of str
        Viseme names in bank order (the client plans the pair tasks from them).
    files : tuple of (str, bytes)
        POSIX paths relative to the bank folder, and contents.
    """

    digest: str
    name: str
    names: Tuple[str, ...]
    files: Tuple[Tuple[str, bytes], ...] = field(repr=False)

    @property
    def nbytes(self) -> int:
        return sum(len(b) for _, b in self.files)


def _digest(files) -> str:
    h = hashlib.sha256(b"lipsync-bank-pack-v1")
    for rel, data in sorted(files):
        h.update(len(rel.encode()).to_bytes(8, "little") + rel.encode())
        h.update(len(data).to_bytes(8, "little"))
        h.update(data)
    return h.hexdigest()


def pack_bank(folder) -> BankPack:
    """Pack a bank folder (validated first: a bad bank raises BankError here, not on a worker).

    Examples
    --------
    >>> from lipsync._data import default_bank_dir
    >>> pack = pack_bank(default_bank_dir())
    >>> pack.files[0][0], len(pack.files), len(pack.digest)
    ('bank.yaml', 10, 64)
    """
    from ..banks.bank import Bank, _read_yaml

    bank = Bank.load(folder)
    folder = bank.path
    _, data = _read_yaml(bank.yaml_path)  # already validated by Bank.load
    rels = ["bank.yaml"]
    for v in bank.names:
        rel = str(PurePosixPath(os.path.normpath(data["visemes"][v]["image"]).replace(os.sep, "/")))
        if rel not in rels:
            rels.append(rel)
    if bank.plate is not None:  # the idle plate of a bank made from video: a worker renders on it too
        rels += [str(PurePosixPath(os.path.normpath(data["plate"][k]).replace(os.sep, "/")))
                 for k in ("video", "poses", "mask")]
    if bank.samples is not None:  # its mouth samples (lipsync.samples): a worker selects from them too
        rels += [str(PurePosixPath(os.path.normpath(data["samples"][k]).replace(os.sep, "/"))) for k in ("video", "table")]
    files = tuple((rel, (folder / rel).read_bytes()) for rel in rels)
    return BankPack(digest=_digest(files), name=bank.name, names=bank.names, files=files)


def default_cache_dir() -> Path:
    """Where a worker keeps unpacked banks and flows: ``$XDG_CACHE_HOME/lipsync/batch``.

    Examples
    --------
    >>> default_cache_dir().parts[-2:]
    ('lipsync', 'batch')
    """
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "lipsync" / "batch"


@dataclass
class LocalBank:
    """A pack unpacked and loaded on this worker: the bank, the shared store, the flows in it."""

    bank: object
    store: object
    folder: Path
    installed: Set[str] = field(default_factory=set)
    lock: threading.Lock = field(default_factory=threading.Lock)
    _normalised: object = None

    def normalised(self):
        """The bank normalised (:func:`lipsync.morphing.normalise.normalise`), once per process."""
        from ..morphing.normalise import normalise

        with self.lock:
            if self._normalised is None:
                self._normalised = normalise(self.bank, cache=self.store)
            return self._normalised


_LOADED: "OrderedDict[Tuple[str, str], LocalBank]" = OrderedDict()
_LOADED_LOCK = threading.Lock()


def _folder_matches(folder: Path, pack: BankPack) -> bool:
    try:
        files = tuple((rel, (folder / rel).read_bytes()) for rel, _ in pack.files)
    except OSError:
        return False
    return _digest(files) == pack.digest


def _unpack(pack: BankPack, cache: Path) -> Path:
    from .._files import atomic_write_bytes

    banks = cache / "banks"
    target = banks / pack.digest
    if target.is_dir() and _folder_matches(target, pack):
        return target
    banks.mkdir(parents=True, exist_ok=True)
    tmp = banks / f".tmp-{os.getpid()}-{os.urandom(4).hex()}"
    try:
        for rel, data in pack.files:
            path = tmp / rel
            if tmp.resolve() not in path.resolve().parents:  # a pack is data: never write outside
                raise ValueError(f"bank pack path {rel!r} leaves the bank folder")
            atomic_write_bytes(path, lambda fh, data=data: fh.write(data))
        if target.exists() and _folder_matches(target, pack):
            return target  # another process on this machine finished unpacking meanwhile
        if target.exists():  # damaged (it did not match): move it aside, then take its place
            aside = banks / f".tmp-{os.getpid()}-{os.urandom(4).hex()}-old"
            try:
                os.rename(target, aside)
                shutil.rmtree(aside, ignore_errors=True)
            except OSError:
                pass
        try:
            os.rename(tmp, target)
        except OSError:  # another process on this machine unpacked it first
            if not _folder_matches(target, pack):
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return target


def local_bank(pack: BankPack, cache: Optional[os.PathLike] = None) -> LocalBank:
    """The pack's bank on this worker: unpacked once per machine, loaded once per process.

    Examples
    --------
    >>> import tempfile
    >>> from lipsync._data import default_bank_dir
    >>> lb = local_bank(pack_bank(default_bank_dir()), tempfile.mkdtemp())
    >>> lb.bank.name, lb.folder.name == pack_bank(default_bank_dir()).digest
    ('toon', True)
    """
    from ..banks.bank import Bank
    from ..morphing.store import FlowStore

    cache = Path(cache) if cache is not None else default_cache_dir()
    key = (str(cache), pack.digest)
    with _LOADED_LOCK:
        got = _LOADED.get(key)
        if got is not None:
            _LOADED.move_to_end(key)
            return got
        folder = _unpack(pack, cache)
        got = LocalBank(bank=Bank.load(folder), store=FlowStore(cache / "store"), folder=folder)
        _LOADED[key] = got
        while len(_LOADED) > MAX_LOADED_BANKS:
            _LOADED.popitem(last=False)
        return got


def install_entries(local: LocalBank, entries) -> int:
    """Write shipped flow store entries ``(key, bytes)`` that this machine's store lacks.

    Entries are whole store files, byte-identical wherever they were computed (the store
    writes them deterministically), so installing is a file write; a damaged one is a
    store miss later (the store checks every entry it reads) and is recomputed, never used.
    Returns the number written.

    Examples
    --------
    >>> import tempfile
    >>> from lipsync._data import default_bank_dir
    >>> from lipsync.batch.worker import pair_task
    >>> pack = pack_bank(default_bank_dir())
    >>> a, b = pack.names[:2]                                         # a pair, in bank order
    >>> entry = pair_task(pack, a, b, tempfile.mkdtemp())             # computed on one machine
    >>> there = local_bank(pack, tempfile.mkdtemp())                  # another machine's cache
    >>> install_entries(there, [entry]), install_entries(there, [entry])
    (1, 0)
    >>> there.store.get_pair(there.bank, a, b) is not None
    True
    """
    from .._files import atomic_write_bytes

    written = 0
    with local.lock:
        for key, data in entries:
            if key in local.installed:
                continue
            path = local.store.pair_path(key)
            if not path.exists():
                atomic_write_bytes(path, lambda fh, data=data: fh.write(data))
                written += 1
            local.installed.add(key)
    return written


def loaded_banks() -> Dict[Tuple[str, str], LocalBank]:
    """The banks this process holds, by (cache folder, digest), for tests and diagnostics.

    Examples
    --------
    >>> isinstance(loaded_banks(), dict)
    True
    """
    with _LOADED_LOCK:
        return dict(_LOADED)
