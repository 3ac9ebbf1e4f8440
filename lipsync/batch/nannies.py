"""The worker host of ``lipsync batch``'s local cluster: ``python -m lipsync.batch.nannies ADDRESS N``.

:func:`lipsync.batch.connect` runs the scheduler in the calling process and starts this
module as a child process, which runs ``N`` dask nannies (each keeping one worker process
alive, restarting it if it dies, as a LocalCluster's would) connected to ``ADDRESS``.

Why not a plain ``LocalCluster(processes=True)``: its nannies start their workers with
multiprocessing's ``spawn``, which re-imports the caller's main module in every worker, so
``run_batch`` from a script without ``if __name__ == "__main__":`` ran that script again in
each worker and failed ("Nanny failed to start", issue 19). Here the main module is this
one, imported by name, and its work is behind the main guard.

Lifetime: the parent holds this process's stdin open and never writes to it; end of file
(the parent closed it, or died and the kernel closed it) ends this process at once, and
each worker process ends with its nanny (dask's own parent-alive pipe). Ctrl-C is left to
the parent (SIGINT ignored here), which closes the scheduler, the workers, then this.
"""

from __future__ import annotations

import asyncio
import logging
import signal
import sys

#: What this process prints on stdout once every nanny and its worker have started.
READY = "lipsync-nannies-ready"
#: On end of file, how long the nannies have to stop their workers before this process
#: exits anyway (the workers then end on their own, with their nanny).
CLOSE_GRACE_S = 5.0


async def _serve(address: str, n: int, stop: asyncio.Event) -> None:
    from distributed import Nanny
    from distributed.worker_memory import parse_memory_limit

    # The options LocalCluster(n_workers=n, threads_per_worker=1, host="127.0.0.1") gives its
    # nannies: one thread, a memory limit of an equal share of the machine, no dashboard.
    options = dict(nthreads=1, host="127.0.0.1", dashboard=False, dashboard_address=None,
                   memory_limit=parse_memory_limit("auto", 1, n, logger=logging.getLogger("distributed")),
                   silence_logs=logging.CRITICAL)
    nannies = [Nanny(address, **options) for _ in range(n)]
    await asyncio.gather(*nannies)  # awaiting a Nanny starts it and its worker
    print(READY, flush=True)
    finished = asyncio.ensure_future(asyncio.gather(*(nanny.finished() for nanny in nannies)))
    stopping = asyncio.ensure_future(stop.wait())
    await asyncio.wait([finished, stopping], return_when=asyncio.FIRST_COMPLETED)
    if stopping.done():  # the parent is done (or gone): stop the workers, as LocalCluster.close does
        await asyncio.gather(*(nanny.close(reason="lipsync-batch-done") for nanny in nannies),
                             return_exceptions=True)
    finished.cancel()
    stopping.cancel()


def main(argv=None) -> int:
    import dask
    from distributed.utils import silence_logging_cmgr

    from .._proc import exit_on_eof

    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2:
        print("usage: python -m lipsync.batch.nannies SCHEDULER_ADDRESS N", file=sys.stderr)
        return 2
    address, n = args[0], int(args[1])
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    loop = asyncio.new_event_loop()
    stop = asyncio.Event()
    exit_on_eof(sys.stdin.buffer, on_eof=lambda: loop.call_soon_threadsafe(stop.set), grace=CLOSE_GRACE_S)
    # Workers start without dask's MALLOC_TRIM_THRESHOLD_ (see lipsync.batch.run.connect);
    # dask's logs silenced as LocalCluster(silence_logs=CRITICAL) does.
    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}), \
            silence_logging_cmgr(logging.CRITICAL):
        try:
            loop.run_until_complete(_serve(address, n, stop))
        finally:
            loop.close()
    return 0


if __name__ == "__main__":
    import os
    import traceback

    try:
        code = main()
    except BaseException:
        traceback.print_exc()
        code = 1
    sys.stdout.flush()
    sys.stderr.flush()
    # Not sys.exit: interpreter shutdown would wait on the thread blocked reading stdin.
    os._exit(code)
