"""``lipsync serve``: render jobs and live talking heads over HTTP and WebSocket, with a demo page."""

from __future__ import annotations

import argparse
import sys

from ..morphing.render import METHODS
from ..motion.timing import timing_names
from ._common import TIMING_HELP, add_bank_option, add_quiet_option, add_store_option


def add_parser(sub) -> None:
    from ..server import (DEFAULT_IDLE_TIMEOUT_S, DEFAULT_MAX_SESSIONS, DEFAULT_MAX_UPLOAD, DEFAULT_QUALITY)
    from ..motion.frames import DEFAULT_FPS
    from ..server.protocol import FPS_CHOICES
    from ..server.jobs import DEFAULT_JOB_TIMEOUT_S, DEFAULT_MAX_CLIP_S

    p = sub.add_parser("serve", help="serve render jobs and live talking heads (HTTP + WebSocket, demo page)",
                       description="Serve POST /api/render (a timeline or audio to an mp4), the live WebSocket "
                                   "/ws/live (events in, frames out on the client's clock) and a demo page. "
                                   "Prints the page's URL, which carries the session token.")
    add_bank_option(p)
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default: 127.0.0.1, this machine only)")
    p.add_argument("--port", type=int, default=8765, metavar="N", help="port (default: 8765; 0 picks a free one)")
    p.add_argument("--max-sessions", type=int, default=DEFAULT_MAX_SESSIONS, metavar="N",
                   help=f"live sessions at once (default: {DEFAULT_MAX_SESSIONS})")
    p.add_argument("--idle-timeout", type=float, default=DEFAULT_IDLE_TIMEOUT_S, metavar="S",
                   help=f"close a live session silent this long (default: {DEFAULT_IDLE_TIMEOUT_S:g} s)")
    p.add_argument("--max-upload-mb", type=float, default=DEFAULT_MAX_UPLOAD / (1 << 20), metavar="MB",
                   help=f"largest request body (default: {DEFAULT_MAX_UPLOAD >> 20} MB)")
    p.add_argument("--max-clip-seconds", type=float, default=DEFAULT_MAX_CLIP_S, metavar="S",
                   help=f"longest render job, seconds of video; longer uploads fail before any frame "
                        f"(default: {DEFAULT_MAX_CLIP_S:g})")
    p.add_argument("--job-timeout", type=float, default=DEFAULT_JOB_TIMEOUT_S, metavar="S",
                   help=f"stop a render job running longer than this, so the jobs queued behind it start "
                        f"(default: {DEFAULT_JOB_TIMEOUT_S:g} s)")
    p.add_argument("--fps", type=float, default=DEFAULT_FPS, choices=FPS_CHOICES, metavar="N",
                   help=f"frame rate of live sessions and render jobs (default: {DEFAULT_FPS:g})")
    p.add_argument("--quality", type=int, default=DEFAULT_QUALITY, metavar="Q",
                   help=f"JPEG/WebP quality of live frames, 10-100 (default: {DEFAULT_QUALITY})")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="renderer threads shared by all sessions (default: one per core)")
    p.add_argument("--method", choices=METHODS.names(), default="flow", help="in-between method (default: flow)")
    p.add_argument("--map", default=None, metavar="NAME_OR_FILE", help="phoneme-to-viseme map")
    p.add_argument("--timing", choices=timing_names(), default=None, metavar="NAME", help=TIMING_HELP)
    from ._samples import add_samples_option

    add_samples_option(p)   # live sessions: a bank's mouth samples, selected within the look-ahead
    add_store_option(p)
    add_quiet_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..errors import check_number
    from ..server import MAX_UPLOAD_LIMIT, ServeConfig, serve

    check_number(args.port, "--port", 0, 65535, integer=True)
    # the other numbers are checked by ServeConfig; this one first, before it becomes bytes
    max_upload_mb = check_number(args.max_upload_mb, "--max-upload-mb", 1 / 1024, MAX_UPLOAD_LIMIT / (1 << 20))
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(f"lipsync serve: warning: listening on {args.host}: other machines can reach this server "
              f"(the token still guards it)", file=sys.stderr)
    config = ServeConfig(bank=args.bank, store=args.store, map=args.map, timing=args.timing, method=args.method,
                         fps=args.fps, quality=args.quality, max_sessions=args.max_sessions,
                         idle_timeout=args.idle_timeout, max_upload=int(max_upload_mb * (1 << 20)),
                         workers=args.workers, quiet=args.quiet, max_clip_seconds=args.max_clip_seconds,
                         job_timeout=args.job_timeout, samples=args.samples)
    try:
        serve(config, host=args.host, port=args.port)
    except KeyboardInterrupt:
        pass
    return 0
