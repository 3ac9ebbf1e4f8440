"""``--live`` and ``--lookahead MS``, shared by ``lipsync render`` and ``lipsync cues``
(what a live session fed the audio shows: :mod:`lipsync.pipeline.liveclip`)."""

from __future__ import annotations

import argparse


def add_live_options(parser: argparse.ArgumentParser) -> None:
    """``--live`` and ``--lookahead MS`` (render and cues)."""
    parser.add_argument("--live", action="store_true",
                        help="audio input: what a live session fed it in real-time 20 ms chunks shows "
                             "(lipsync serve, LiveAnimator.feed_audio): causal, no transcript")
    parser.add_argument("--lookahead", type=float, default=None, metavar="MS",
                        help="with --live: audio past a frame's time it is made with, in ms (default: 200)")


def lookahead_seconds(args: argparse.Namespace):
    """``--lookahead`` in seconds (None: the default); refused without ``--live``."""
    from ..errors import InputError, check_number

    ms = getattr(args, "lookahead", None)
    if ms is None:
        return None
    if not getattr(args, "live", False):
        raise InputError("--lookahead goes with --live")
    check_number(ms, "--lookahead", 0, 1000)
    return ms / 1000.0
