"""Batch preprocessing: compute every missing pair flow of a bank into its flow store.

Each entry holds both flows and their inverse maps at t = k/4 (Newton's method, see
:func:`lipsync.morphing.flows.inverse_tables`), so rendering a frame never solves anything.

Pairs are independent, so they are computed in parallel by threads of the calling process
(one pair per task). The work runs outside the GIL: the Beier-Neely field in a numba
``nogil`` kernel (lipsync.morphing.warp), the inverse tables in OpenCV's remap and large numpy
operations, the entry's CRC in zlib and its write in the OS. Threads, not worker processes:
a library must work from any script, notebook or REPL, and a ``spawn`` process pool
re-imports the caller's main module in every child, so a plain script without
``if __name__ == "__main__":`` ran again in each worker and died with BrokenProcessPool
(issue 19). Threads also cannot outlive their process. Measured on the toon's 36 pairs
(one run, 2 cores): see the ``preprocess`` figure of ``python -m lipsync.bench``.

Each task writes its entry itself, atomically; an interrupted run leaves only whole
entries behind, and the next run computes just what is missing.
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

from ..banks.bank import Bank
from .flows import pair_flows
from .normalise import NormalisedBank, normalise
from .store import FlowStore


@dataclass(frozen=True)
class PreprocessReport:
    """What a preprocessing run did.

    Attributes
    ----------
    pairs : int
        Unordered viseme pairs in the bank.
    computed, reused : int
        Pairs computed now, and pairs whose stored entry was valid.
    seconds : float
        Wall time.
    store_bytes : int
        Bytes on disk of the whole store afterwards.
    stale : int
        Entries in the store that this bank no longer uses (old images, lines or
        parameters); removed when ``prune`` was asked for.
    pruned : bool
        Whether the stale entries were removed.
    """

    pairs: int
    computed: int
    reused: int
    seconds: float
    store_bytes: int
    stale: int = 0
    pruned: bool = False

    def summary(self) -> str:
        text = (f"{self.pairs} pairs: {self.computed} computed, {self.reused} reused in "
                f"{self.seconds:.1f} s; store {self.store_bytes / 1e6:.1f} MB")
        if self.stale:
            text += (f"; {self.stale} stale entries removed" if self.pruned else
                     f"; {self.stale} stale entries (--prune removes them)")
        return text


def all_pairs(names) -> List[Tuple[str, str]]:
    """Unordered pairs in bank order: (A, B) with A before B."""
    return [(names[i], names[j]) for i in range(len(names)) for j in range(i + 1, len(names))]


def bank_pair_flows(nb: NormalisedBank, a: str, b: str) -> Tuple[np.ndarray, np.ndarray, Optional[float]]:
    """What a bank's store entry for the pair (a, b) holds: ``(forward, backward, axis)``.

    The line flows of :func:`lipsync.morphing.flows.pair_flows` on the normalised bank ``nb``, refined by optical
    flow (:func:`lipsync.morphing.refine.refine_pair`) unless the bank says ``refine: false``, and
    the mirror axis to store them with (the bank's; refined flows of a symmetric bank are
    made symmetric too). Every place that computes store entries (preprocess, the renderer
    on a miss, the editor, batch workers) calls this.

    Examples
    --------
    >>> from lipsync._data import default_bank_dir
    >>> nb = normalise(Bank.load(default_bank_dir()))
    >>> fwd, bwd, axis = bank_pair_flows(nb, "X", "D")
    >>> fwd.shape == nb.shape + (2,)
    True
    """
    bank = nb.bank
    forward, backward = pair_flows(nb.shape, nb.lines[a], nb.lines[b], bank.warp,
                                   line_names=bank.line_names, axis=nb.axis)
    if not bank.refine:
        return forward, backward, nb.axis
    from .refine import refine_pair

    forward, backward = refine_pair(nb.images[a], nb.images[b], forward, backward, axis=nb.axis)
    return forward, backward, nb.axis


def _compute_pair(root: str, key: str, nb: NormalisedBank, a: str, b: str) -> str:
    # One task (a thread here, a dask worker in lipsync.batch): both fields, the entry written atomically.
    forward, backward, axis = bank_pair_flows(nb, a, b)
    FlowStore(root).put_pair(key, forward, backward, axis=axis, names=(a, b))
    return key


def preprocess(bank: Bank, *, store: Optional[FlowStore] = None, jobs: Optional[int] = None,
               quiet: bool = False, normalised: Optional[NormalisedBank] = None,
               prune: bool = False) -> PreprocessReport:
    """Compute the flows of every pair of ``bank`` that its store lacks.

    Parameters
    ----------
    bank : Bank
        A loaded bank.
    store : FlowStore, optional
        Where flows go; by default ``<bank>/.lipsync``.
    jobs : int, optional
        Threads computing pairs; default: all cores. 1 computes in the calling thread.
    quiet : bool
        No progress bar.
    normalised : NormalisedBank, optional
        The bank already normalised (saves the work when the caller has it).
    prune : bool
        Remove store entries this bank no longer uses. Only for a store that holds one
        bank (the default ``<bank>/.lipsync``): another bank's entries look stale too.

    Returns
    -------
    PreprocessReport

    Examples
    --------
    >>> import tempfile
    >>> from lipsync._data import default_bank_dir
    >>> bank = Bank.load(default_bank_dir())
    >>> report = preprocess(bank, store=FlowStore(tempfile.mkdtemp()), jobs=2, quiet=True)
    >>> report.computed == report.pairs == 36
    True
    """
    from tqdm import tqdm

    t0 = time.perf_counter()
    store = store or FlowStore.for_bank(bank)
    store.root.mkdir(parents=True, exist_ok=True)
    store.clean_temps()
    nb = normalised or normalise(bank, cache=store)
    pairs = all_pairs(bank.names)
    todo = []
    for a, b in pairs:
        key = store.pair_key(bank, a, b, nb.axis)
        if store.load_pair(key, bank.shape) is None:
            todo.append((str(store.root), key, nb, a, b))
    jobs = max(1, int(jobs if jobs is not None else (os.cpu_count() or 1)))
    bar = tqdm(total=len(todo), desc=f"flows {bank.name}", unit="pair", disable=quiet or not todo,
               leave=False)
    try:
        if jobs == 1 or len(todo) <= 1:
            for task in todo:
                _compute_pair(*task)
                bar.update(1)
        else:
            with ThreadPoolExecutor(max_workers=min(jobs, len(todo)), thread_name_prefix="lipsync-flows") as ex:
                futures = [ex.submit(_compute_pair, *task) for task in todo]
                try:
                    for fut in as_completed(futures):
                        fut.result()
                        bar.update(1)
                except BaseException:
                    # Ctrl-C or a failed pair: queued pairs are dropped; the running ones
                    # finish their (atomic) writes before the pool shuts down.
                    for fut in futures:
                        fut.cancel()
                    raise
    finally:
        bar.close()
    keep = {store.pair_path(store.pair_key(bank, a, b, nb.axis)) for a, b in pairs}
    keep |= {store.image_path(store.image_key(bank, v, nb.axis)) for v in bank.names}
    stale = [p for p in store.entries() if p not in keep]
    if prune:
        for p in stale:
            p.unlink(missing_ok=True)
    return PreprocessReport(pairs=len(pairs), computed=len(todo), reused=len(pairs) - len(todo),
                            seconds=time.perf_counter() - t0, store_bytes=store.size_bytes(),
                            stale=len(stale), pruned=prune)

