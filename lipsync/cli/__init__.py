"""Command-line interface: one module per ``lipsync`` command, options they share in ``_common``.

Exit codes (DESIGN.md): 0 success, 2 bad input (the message names the file and, where it
applies, the line), 130 interrupted, 1 anything else.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from typing import Callable, List, Optional

from ..errors import InputError, TranscriptMismatch

EXIT_OK, EXIT_FAILURE, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
#: After SIGTERM: 128 + 15, the shell's convention for "ended by signal 15".
EXIT_TERMINATED = 143

# Each command module exposes ``add_parser(subparsers)`` that registers its parser with
# ``set_defaults(func=run)``; ``run(args) -> int``. Listed here so --help shows them in the
# order a user meets them: make video, inspect timing, prepare a subject, then services.
_COMMAND_MODULES = [
    "render",
    "dub",
    "align",
    "cues",
    "atlas",
    "timeline",
    "init",
    "check",
    "preview",
    "edit",
    "edit_timeline",  # `lipsync edit-timeline`
    "preprocess",
    "morph",
    "serve",
    "batch",
    "languages",
    "blender_addon",  # `lipsync blender-addon`: a command's dashes are underscores in its module name
]


class _Parser(argparse.ArgumentParser):
    """argparse exits with 2 on usage errors already; keep that, and say which command."""


def build_parser(argv: Optional[List[str]] = None) -> argparse.ArgumentParser:
    """The ``lipsync`` argument parser.

    Parameters
    ----------
    argv : list of str, optional
        The arguments about to be parsed. When they start with a command's name only that
        command's module is imported: each pulls in what it runs on (``serve`` starlette,
        ``batch`` dask, ``cues`` the writers, ...), and ``lipsync render`` should not pay
        for the others (about 40 ms of its start-up). Otherwise every command is registered,
        so ``lipsync --help`` and a mistyped command list them all.

    Returns
    -------
    argparse.ArgumentParser
    """
    import importlib

    parser = _Parser(prog="lipsync", description="Speech to talking-head video by morphing between viseme images.")
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"lipsync {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    names = _COMMAND_MODULES
    if argv and argv[0].replace("-", "_") in _COMMAND_MODULES:
        names = [argv[0].replace("-", "_")]
    for name in names:
        try:
            module = importlib.import_module(f".{name}", __package__)
        except ModuleNotFoundError as exc:  # a command not built yet must not break the others
            if exc.name == f"{__package__}.{name}":
                continue
            raise
        module.add_parser(sub)
    return parser


def _format_warning(message, category, filename, lineno, line=None):
    # Users see "lipsync: warning: <what>", not Python's source location.
    return f"lipsync: warning: {message}\n"


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of the ``lipsync`` console script; returns the exit code."""
    import warnings

    from ..encode import EncodeError

    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv)
    args, extra = parser.parse_known_args(argv)
    # argparse takes a command's positionals in one run: `lipsync atlas BANK -o OUT T1 T2`
    # would leave T1 T2 unrecognised. A command naming a list positional in
    # ``extra_positionals`` gets them appended (options it does not know are still errors).
    target = getattr(args, "extra_positionals", None)
    if extra:
        if target is None or any(e.startswith("-") for e in extra):
            parser.parse_args(argv)  # argparse's own message and exit code 2
        getattr(args, target).extend(extra)
    func: Callable[[argparse.Namespace], int] = args.func
    saved = warnings.formatwarning
    warnings.formatwarning = _format_warning
    terminated: List[int] = []
    saved_term = _on_sigterm(terminated)
    try:
        if getattr(args, "allow_mismatch", True) is False:
            warnings.filterwarnings("error", category=TranscriptMismatch)
        from ._common import check_outputs_apart

        check_outputs_apart(args)   # an output never replaces an input (issue 38)
        return int(func(args) or 0)
    except InputError as exc:
        print(f"lipsync: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except TranscriptMismatch as exc:
        print(f"lipsync: error: {exc}; stopped, nothing written: if it is the right transcript, "
              f"--allow-mismatch goes on",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        if terminated:
            print("lipsync: terminated (SIGTERM); no partial output was left behind", file=sys.stderr)
            return EXIT_TERMINATED
        print("lipsync: interrupted; no partial output was left behind", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        return EXIT_FAILURE
    except (OSError, EncodeError) as exc:
        print(f"lipsync: error: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    finally:
        warnings.formatwarning = saved
        if getattr(args, "allow_mismatch", True) is False:
            warnings.filters[:] = [f for f in warnings.filters if f[2] is not TranscriptMismatch]
        if saved_term is not None:
            signal.signal(signal.SIGTERM, saved_term)


def _on_sigterm(record: List[int]):
    """SIGTERM (what ``kill``, systemd and ``docker stop`` send) handled as Ctrl-C is: the
    running command unwinds through its cleanup (temporary outputs, a server's job folder)
    instead of dying where it stands. Returns the previous handler (None off the main thread,
    where Python cannot set one)."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum, frame):
        record.append(signum)
        raise KeyboardInterrupt

    return signal.signal(signal.SIGTERM, handler)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
