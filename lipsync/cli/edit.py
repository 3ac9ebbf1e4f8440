"""``lipsync edit BANK``: the browser editor for control lines, with a live morph preview."""

from __future__ import annotations

import argparse

from ._common import add_store_option


def add_parser(sub) -> None:
    p = sub.add_parser("edit", help="edit a bank's control lines in the browser (local server)")
    p.add_argument("bank", help="bank folder (with bank.yaml; make one with lipsync init), or a shipped subject's name (toon, grid-s1)")
    p.add_argument("--port", type=int, default=0, metavar="N", help="port on 127.0.0.1 (default: a free one)")
    p.add_argument("--open", action="store_true", help="open the page in the default browser")
    add_store_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..editor import Editor, make_app
    from ..errors import InputError
    from ..morphing.store import FlowStore
    from ..web import Session, run as serve

    if not 0 <= args.port <= 65535:
        raise InputError(f"--port must be 0..65535, got {args.port}")
    session = Session.open("127.0.0.1", args.port)  # a taken port fails before any work
    editor = None
    try:
        editor = Editor(args.bank, store=FlowStore(args.store) if args.store else None)
        app = make_app(editor, session)
        if args.open:
            import threading
            import webbrowser

            # After the server has started listening (run() below blocks).
            opener = threading.Timer(0.5, webbrowser.open, (session.url("/"),))
            opener.daemon = True
            opener.start()
        print(f"editing {editor.yaml_path} (Ctrl-C to stop)", flush=True)
        serve(app, session, announce="lipsync edit: open")
    finally:
        if editor is not None:
            editor.close()
        session.close()
    return 0
