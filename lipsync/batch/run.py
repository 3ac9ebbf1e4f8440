"""The client side of a batch: plan, connect, submit, collect, report.

Order of work (each stage once):

1. :func:`~lipsync.batch.manifest.read_manifest` checks every row (exit 2 before any work);
2. every bank in use is packed (:func:`~lipsync.batch.bankpack.pack_bank`) and every row
   keyed (:func:`~lipsync.batch.sidecar.clip_key`); rows whose output is current are skipped,
   and when nothing is left no cluster is started;
3. on the cluster (a LocalCluster of processes on 127.0.0.1, or a running scheduler): each
   bank pack is scattered once, one :func:`~lipsync.batch.worker.pair_task` per viseme pair
   computes the flows (once per cluster), and the clip tasks depend on those results, so
   dask copies each entry to each worker once and keeps it there;
4. clip tasks are submitted through a bounded window (the client never holds every input
   in memory, the scheduler never holds every task), results are written as they arrive
   (video, then sidecar, both atomically) and the report is written at the end, also when
   interrupted.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import logging
import os
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Tuple

from ..errors import InputError
from .bankpack import BankPack, pack_bank
from .manifest import ClipJob, ManifestError, read_manifest
from .sidecar import clip_key, read_done, write_done
from .worker import ClipTask, clip_task, pair_task

PathLike = os.PathLike

#: Clip tasks in flight per worker thread: enough that a worker never waits for the client
#: to hand it the next clip (one running, one or two queued), few enough that inputs and
#: results in memory stay a handful per worker whatever the manifest's length.
WINDOW_PER_THREAD = 3
#: Report file written into OUTDIR when ``--report`` is not given.
DEFAULT_REPORT = "lipsync-batch-report.json"
#: How long to wait for a --scheduler to answer: a cluster that does not answer in this
#: long is down or unreachable, and saying so beats hanging.
CONNECT_TIMEOUT_S = 20
_ADDRESS = re.compile(r"^(tcp|tls|inproc|ws|wss)://[^\s/]+$")
REPORT_FIELDS = ("line", "input", "output", "status", "error", "frames", "seconds", "render_seconds", "worker")


@dataclass
class ClipResult:
    """One report row."""

    line: int
    input: str
    output: str
    status: str = "not run"   # done | skipped | failed | not run
    error: str = ""
    frames: int = 0
    seconds: float = 0.0
    render_seconds: float = 0.0
    worker: str = ""


@dataclass
class BatchReport:
    """What :func:`run_batch` did.

    Attributes
    ----------
    clips : list of ClipResult
        One per manifest row, in manifest order.
    wall_seconds : float
        From reading the manifest to the last result.
    cluster : str
        The cluster used ("" when every clip was skipped).
    report_path : Path
    """

    clips: List[ClipResult]
    wall_seconds: float
    cluster: str = ""
    report_path: Optional[Path] = None

    def count(self, status: str) -> int:
        return sum(1 for c in self.clips if c.status == status)

    @property
    def done(self) -> int:
        return self.count("done")

    @property
    def skipped(self) -> int:
        return self.count("skipped")

    @property
    def failed(self) -> int:
        return self.count("failed")

    @property
    def video_seconds(self) -> float:
        """Seconds of video rendered in this run (skipped clips not counted)."""
        return sum(c.seconds for c in self.clips if c.status == "done")

    @property
    def realtime_factor(self) -> float:
        """Seconds of video rendered per second of wall time."""
        return self.video_seconds / max(self.wall_seconds, 1e-9)

    def summary(self) -> str:
        not_run = self.count("not run")
        extra = f", {not_run} not run" if not_run else ""
        return (f"{len(self.clips)} clips: {self.done} done, {self.skipped} skipped, {self.failed} failed{extra}; "
                f"{self.video_seconds:.1f} s of video in {self.wall_seconds:.1f} s wall "
                f"({self.realtime_factor:.2f}x real time)"
                + (f"; report {self.report_path}" if self.report_path else ""))


def _write_report(path: Path, report: BatchReport) -> None:
    from .._files import atomic_write_bytes

    rows = [{k: getattr(c, k) for k in REPORT_FIELDS} for c in report.clips]
    if path.suffix.lower() == ".csv":
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=REPORT_FIELDS, lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
        text = buf.getvalue()
    else:
        text = json.dumps({"summary": {"clips": len(report.clips), "done": report.done, "skipped": report.skipped,
                                       "failed": report.failed, "video_seconds": round(report.video_seconds, 3),
                                       "wall_seconds": round(report.wall_seconds, 3),
                                       "realtime_factor": round(report.realtime_factor, 3),
                                       "cluster": report.cluster},
                           "clips": rows}, indent=1) + "\n"
    atomic_write_bytes(path, lambda fh: fh.write(text.encode()))


@contextlib.contextmanager
def _ctrl_c_after_this() -> Iterator[None]:
    """Hold a Ctrl-C until the block is over, then raise it.

    Writing a finished clip (video, then sidecar) and marking it done in the report must
    not be cut in two: an interrupted batch leaves whole videos, each with its sidecar and
    each reported as done. Outside the main thread signals cannot be handled, so nothing
    is deferred there.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: List[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        raise KeyboardInterrupt


@contextlib.contextmanager
def _workers_ignore_ctrl_c() -> Iterator[None]:
    """Start processes with SIGINT ignored (inherited through exec; Python keeps it so).

    Ctrl-C in a terminal reaches the whole process group: without this every worker
    prints a KeyboardInterrupt traceback while this process is already shutting the
    cluster down in order.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextlib.contextmanager
def connect(workers: Optional[int] = None, scheduler: Optional[str] = None) -> Iterator[Tuple[object, str]]:
    """A dask ``Client``: on a new LocalCluster of ``workers`` processes, or on ``scheduler``.

    The LocalCluster binds 127.0.0.1 only, has no dashboard, one thread per worker (a clip
    already keeps two threads and an ffmpeg process busy) and is shut down, workers and
    ports included, when the block ends, also on errors and Ctrl-C.

    Examples
    --------
    >>> with connect(workers=2) as (client, where):                   # doctest: +SKIP
    ...     print(where, sum(client.nthreads().values()))
    LocalCluster tcp://127.0.0.1:40123 (2 worker processes) 2
    """
    from distributed import Client, LocalCluster

    if scheduler is not None:
        if not _ADDRESS.match(scheduler):
            raise InputError(f"--scheduler wants an address like tcp://HOST:PORT, got {scheduler!r}")
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise OSError(f"cannot reach the dask scheduler at {scheduler}: {exc}") from None
        with client:
            yield client, f"scheduler {scheduler}"
        return
    n = workers if workers is not None else (os.cpu_count() or 1)
    if n < 1:
        raise InputError(f"--workers must be at least 1, got {n}")
    # The scheduler runs here, in a LocalCluster with no workers of its own; the workers'
    # nannies run in a child process started as `python -m lipsync.batch.nannies` (a
    # LocalCluster's own nannies spawn their workers by re-importing the caller's main
    # module: a script without a main guard ran again in each). The scheduler always
    # serves HTTP (health, metrics): on 127.0.0.1 at a free port, not on the dashboard's
    # 8787 (taken by any other cluster on the machine); no dashboard pages. Worker processes
    # start without dask's MALLOC_TRIM_THRESHOLD_: setting it turns off glibc's adaptive
    # mmap threshold, so every frame-sized temporary is mmapped and page-faulted afresh;
    # measured here, it costs a clip +34% CPU and up to twice the wall time
    # (docs/scaling.md). Dask's one-thread OpenMP/BLAS settings stay. Its own logs are
    # silenced: a heartbeat racing the shutdown is logged as an error, and what matters to
    # the user (a clip failed, a worker died) is in the report.
    cluster = LocalCluster(n_workers=0, processes=False, protocol="tcp://", host="127.0.0.1",
                           dashboard_address="127.0.0.1:0", scheduler_kwargs={"dashboard": False},
                           silence_logs=logging.CRITICAL)
    with cluster:
        host = _start_worker_host(cluster.scheduler_address, n)
        try:
            _wait_until_ready(host)
            with Client(cluster, set_as_default=False) as client:
                _wait_for_workers(client, n, host)
                yield client, f"LocalCluster {cluster.scheduler_address} ({n} worker process{'es' if n > 1 else ''})"
        finally:
            _stop_worker_host(host)


#: Longest wait for the local workers to start (a cold start imports numpy, OpenCV and
#: dask in each: seconds; a busy machine: tens of seconds).
WORKER_START_TIMEOUT_S = 180
#: How long the worker host may take to stop its workers before it is killed (its workers
#: end with it: they watch their nanny).
WORKER_HOST_EXIT_S = 15


def _start_worker_host(address: str, n: int):
    """The child process running ``n`` nannies for the scheduler at ``address`` (lipsync.batch.nannies)."""
    import subprocess

    with _workers_ignore_ctrl_c():
        return subprocess.Popen([sys.executable, "-m", "lipsync.batch.nannies", address, str(n)],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE)


def _wait_until_ready(host) -> None:
    """Until the host says all its nannies have started; an error if it exits first."""
    import threading

    from .nannies import READY

    line: List[bytes] = []
    reader = threading.Thread(target=lambda: line.append(host.stdout.readline()), daemon=True)
    reader.start()
    reader.join(WORKER_START_TIMEOUT_S)
    if not line:
        raise RuntimeError(f"the local dask workers did not start within {WORKER_START_TIMEOUT_S} s")
    if line[0].strip() != READY.encode():
        host.wait()
        raise RuntimeError(f"the local dask workers could not start (their host exited with {host.returncode})")


def _stop_worker_host(proc) -> None:
    """Close the host's stdin (it then stops its nannies and workers and exits); wait for it."""
    import subprocess

    proc.stdin.close()
    try:
        proc.wait(WORKER_HOST_EXIT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    proc.stdout.close()


def _wait_for_workers(client, n: int, host) -> None:
    """Until ``n`` workers are connected; an error naming the cause if the host died first."""
    deadline = time.monotonic() + WORKER_START_TIMEOUT_S
    while len(client.scheduler_info(n_workers=-1)["workers"]) < n:
        if host.poll() is not None:
            raise RuntimeError(f"the local dask workers could not start (their host exited with {host.returncode})")
        if time.monotonic() > deadline:
            raise RuntimeError(f"the local dask workers did not start within {WORKER_START_TIMEOUT_S} s")
        time.sleep(0.05)


def _task(job: ClipJob) -> ClipTask:
    files = {"input": (job.input.name, job.input.read_bytes(), str(job.input))}
    if job.audio:
        files["audio"] = (job.audio.name, job.audio.read_bytes(), str(job.audio))
    if job.text_file:
        files["text"] = (job.text_file.name, job.text_file.read_bytes(), str(job.text_file))
    if job.map_file:
        files["map"] = (job.map_file.name, job.map_file.read_bytes(), str(job.map_file))
    return ClipTask(line=job.line, output=job.output, files=files, text=job.text, fps=job.fps, map=job.map,
                    timing=job.timing, method=job.method)


def run_batch(manifest: PathLike, outdir: PathLike, *, workers: Optional[int] = None,
              scheduler: Optional[str] = None, report: Optional[PathLike] = None,
              cache: Optional[str] = None, quiet: bool = False) -> BatchReport:
    """Render every clip of a manifest on a dask.distributed cluster.

    Parameters
    ----------
    manifest : path-like
        CSV (with a header) or JSON lines; see :mod:`lipsync.batch.manifest`.
    outdir : path-like
        Where outputs (and their ``.lipsync.json`` sidecars) go; created if missing.
    workers : int, optional
        Worker processes of the LocalCluster started for this batch (default: one per core).
    scheduler : str, optional
        Address of a running dask scheduler (``tcp://HOST:PORT``) to use instead.
    report : path-like, optional
        The report (``.json``, or ``.csv``); default ``OUTDIR/lipsync-batch-report.json``.
    cache : str, optional
        Folder *on the workers* for unpacked banks and flows (default
        ``$XDG_CACHE_HOME/lipsync/batch`` there).
    quiet : bool
        No progress bar.

    Returns
    -------
    BatchReport

    Raises
    ------
    ManifestError
        Bad rows (each with its line), before anything runs.

    Examples
    --------
    >>> import os, tempfile
    >>> d = tempfile.mkdtemp()
    >>> _ = open(os.path.join(d, "a.tsv"), "w").write("0.00\\tX\\n0.40\\tD\\n0.80\\tX\\n")
    >>> _ = open(os.path.join(d, "m.csv"), "w").write("input,output\\na.tsv,a.mp4\\n")
    >>> r = run_batch(os.path.join(d, "m.csv"), os.path.join(d, "out"), workers=1,
    ...               cache=os.path.join(d, "cache"), quiet=True)      # doctest: +SKIP
    >>> r.done, r.clips[0].frames                                      # doctest: +SKIP
    (1, 20)
    """
    from tqdm import tqdm

    t0 = time.perf_counter()
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")
    if scheduler is not None and not _ADDRESS.match(scheduler):
        raise InputError(f"--scheduler wants an address like tcp://HOST:PORT, got {scheduler!r}")
    outdir = Path(outdir)
    jobs = read_manifest(manifest, outdir)
    report_path = Path(report) if report is not None else outdir / DEFAULT_REPORT
    if report_path.suffix.lower() not in (".json", ".csv"):
        raise InputError("the report is .json or .csv", path=report_path)
    outdir.mkdir(parents=True, exist_ok=True)

    packs: Dict[Path, BankPack] = {}
    for job in jobs:
        if job.bank not in packs:
            try:
                packs[job.bank] = pack_bank(job.bank)
            except InputError as exc:  # changed since the manifest was checked
                raise ManifestError(manifest, [(job.line, f"bank: {exc}")]) from None
    results = [ClipResult(line=j.line, input=str(j.input), output=j.output) for j in jobs]
    keys = [clip_key(j, packs[j.bank].digest) for j in jobs]
    todo: List[int] = []
    for i, job in enumerate(jobs):
        meta = read_done(outdir / job.output, keys[i])
        if meta is None:
            todo.append(i)
        else:
            r = results[i]
            r.status, r.frames, r.seconds = "skipped", int(meta.get("frames", 0)), float(meta.get("seconds", 0.0))
    batch = BatchReport(clips=results, wall_seconds=0.0, report_path=report_path)
    bar = tqdm(total=len(jobs), initial=len(jobs) - len(todo), desc="batch", unit="clip", disable=quiet)
    try:
        if todo:
            with connect(workers, scheduler) as (client, cluster):
                batch.cluster = cluster
                if not quiet:
                    bar.write(f"lipsync batch: {len(todo)} of {len(jobs)} clips to render on {cluster}",
                              file=sys.stderr)
                _execute(client, jobs, todo, keys, packs, results, outdir, cache, bar)
    finally:
        bar.close()
        batch.wall_seconds = time.perf_counter() - t0
        _write_report(report_path, batch)
    return batch


def _execute(client, jobs: List[ClipJob], todo: List[int], keys: List[str], packs: Dict[Path, BankPack],
             results: List[ClipResult], outdir: Path, cache: Optional[str], bar) -> None:
    from distributed import as_completed

    from .. import __version__
    from ..morphing.preprocess import all_pairs

    needed = {jobs[i].bank for i in todo}
    pack_futures = {}
    pair_futures = {}
    for bank in needed:
        pack = packs[bank]
        [pack_futures[bank]] = client.scatter([pack], hash=False)
        # Keys name the content, so two batches on one cluster share a bank's pair tasks.
        pair_futures[bank] = [client.submit(pair_task, pack_futures[bank], a, b, cache, pure=False,
                                            key=f"lipsync-pair-{pack.digest[:16]}-{a}-{b}")
                              for a, b in all_pairs(pack.names)]
    n_threads = max(1, sum(client.nthreads().values()))
    window = WINDOW_PER_THREAD * n_threads
    queue = iter(todo)
    index_of = {}
    ac = as_completed(loop=client.loop)

    def submit_next() -> bool:
        i = next(queue, None)
        if i is None:
            return False
        job = jobs[i]
        fut = client.submit(clip_task, _task(job), pack_futures[job.bank], pair_futures[job.bank], cache,
                            pure=False, key=f"lipsync-clip-{job.line}-{keys[i][:16]}")
        index_of[fut.key] = i
        ac.add(fut)
        return True

    for _ in range(window):
        if not submit_next():
            break
    for fut in ac:
        i = index_of.pop(fut.key)
        r = results[i]
        try:
            res = fut.result()
        except Exception as exc:  # the task itself could not run (e.g. its worker died repeatedly)
            res = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
        fut.release()
        r.render_seconds = round(float(res.get("render_seconds", 0.0)), 3)
        r.worker = f"{res.get('host', '')}:{res.get('pid', '')}" if "pid" in res else ""
        if res.get("ok") and res.get("version") != __version__:
            res = {"ok": False, "error": f"worker has lipsync {res.get('version')}, this client {__version__}: "
                                         f"install the same version on the workers"}
        if res.get("ok"):
            with _ctrl_c_after_this():
                try:
                    write_done(outdir / jobs[i].output, res["data"], keys[i],
                               {"frames": res["frames"], "fps": res["fps"], "seconds": res["seconds"],
                                "input": str(jobs[i].input), "line": jobs[i].line})
                    r.status, r.frames, r.seconds = "done", int(res["frames"]), round(float(res["seconds"]), 3)
                except OSError as exc:
                    r.status, r.error = "failed", f"writing {outdir / jobs[i].output}: {exc}"
        else:
            r.status, r.error = "failed", res.get("error", "unknown error")
        bar.update(1)
        submit_next()
    for futs in pair_futures.values():
        for f in futs:
            f.release()
    for f in pack_futures.values():
        f.release()
