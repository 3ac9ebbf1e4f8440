"""Child processes that end with their parent.

lipsync starts few processes of its own (flows are computed in threads; ffmpeg is a pipe
that ends when its input does). Where it does -- forked speech-recognition workers
(:mod:`lipsync.speech.align`) and the process hosting a local dask cluster's workers
(:mod:`lipsync.batch.nannies`) -- a parent killed with SIGKILL (an OOM killer, ``kill -9``,
a crashed notebook kernel) must not leave them running: they would hold CPU, memory and
ports for as long as their work lasts, or for ever when they wait on a queue nobody fills.

Two mechanisms, both in the child:

* :func:`die_with_parent`: Linux's ``prctl(PR_SET_PDEATHSIG)``, a signal the kernel sends
  when the parent *thread* exits (so only for children of a thread that outlives them, as
  the main thread does), or elsewhere a thread polling ``getppid()``;
* :func:`exit_on_eof`: a thread reading a pipe the parent holds open and nobody writes;
  end of file means every copy of the parent's end is closed -- the parent is gone or
  wants the child gone -- whichever thread started the child.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from typing import BinaryIO, Callable, Optional

#: prctl option number (linux/prctl.h).
_PR_SET_PDEATHSIG = 1
#: How often the portable fallback looks at the parent's pid: a dead parent's workers stop
#: within this, and a sleeping thread costs nothing meanwhile.
POLL_S = 0.5


def die_with_parent(parent_pid: int, sig: int = signal.SIGKILL) -> None:
    """End this process (with ``sig``) when the process ``parent_pid`` that started it dies.

    Call it first thing in the child, with the parent's pid taken *before* the child was
    started: if the parent died in between, this process exits at once.

    Examples
    --------
    >>> import subprocess
    >>> code = "import os; from lipsync._proc import die_with_parent; die_with_parent(os.getppid()); print('ok')"
    >>> subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout
    'ok\\n'
    """
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            if libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0:
                if os.getppid() != parent_pid:  # died before prctl took effect
                    os._exit(1)
                return
        except (OSError, AttributeError):  # no libc prctl: fall back to polling
            pass
    if os.getppid() != parent_pid:
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(POLL_S)
        os._exit(1)

    threading.Thread(target=watch, name="lipsync-parent-watch", daemon=True).start()


def exit_on_eof(stream: BinaryIO, code: int = 0, *, on_eof: Optional[Callable[[], None]] = None,
                grace: float = 0.0) -> threading.Thread:
    """Exit this process (``os._exit(code)``) when ``stream`` reaches end of file.

    For a child started with ``stdin=subprocess.PIPE`` whose parent never writes: the
    parent closes its end (or dies, and the kernel closes it) to end the child. ``on_eof``
    is called first (from the watching thread), to begin a clean shutdown; the process
    exits ``grace`` seconds later whether or not that has finished. Returns the watching
    (daemon) thread.

    Examples
    --------
    >>> import subprocess
    >>> code = "import sys, time; from lipsync._proc import exit_on_eof; exit_on_eof(sys.stdin.buffer, 3); time.sleep(60)"
    >>> child = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE)
    >>> child.stdin.close()      # the parent lets go (or dies): the child ends
    >>> child.wait(30)
    3
    """
    def watch() -> None:
        try:
            while stream.read(4096):
                pass
        except (OSError, ValueError):
            pass
        if on_eof is not None:
            try:
                on_eof()
            except Exception:  # the exit below must happen regardless
                pass
            time.sleep(grace)
        os._exit(code)

    t = threading.Thread(target=watch, name="lipsync-parent-pipe", daemon=True)
    t.start()
    return t
