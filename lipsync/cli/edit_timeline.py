"""``lipsync edit-timeline AUDIO``: correct a recording's lip-sync timing in the browser."""

from __future__ import annotations

import argparse

from ._common import add_bank_option, add_quiet_option, add_store_option, lang_code


def add_parser(sub) -> None:
    from ..timing_editor.model import MAX_AUDIO_S

    p = sub.add_parser("edit-timeline", help="correct a recording's words, phones and visemes in the browser, "
                                             "with the mouth previewed (local server)",
                       description="Open a local page showing the recording's waveform, its words, phones and "
                                   "visemes (aligned from --text, or read from --timeline), and the bank's mouth "
                                   "in sync; drag, retype and save as TextGrid, .pgo, Rhubarb or Moho. The URL "
                                   f"printed carries the session token. Recordings up to {MAX_AUDIO_S / 3600:g} h.")
    p.add_argument("audio", metavar="AUDIO", help="the speech recording (wav, flac, mp3, a video's sound, ...)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--text", default=None, metavar="TEXT_OR_FILE",
                     help="its transcript (or a file holding it): the words are aligned (default: recognised)")
    src.add_argument("--timeline", default=None, metavar="FILE",
                     help="start from this timeline (TextGrid, Papagayo .pgo, Rhubarb .tsv/.json, Moho .dat, "
                          "GRID .align, any format lipsync reads)")
    p.add_argument("--lang", type=lang_code, default=None, metavar="CODE",
                   help="the speech's language (BCP 47; default English): aligner and retyped words' phones")
    add_bank_option(p)
    p.add_argument("--fps", type=float, default=25.0, metavar="N",
                   help="frame rate: the grid times snap to and the preview's (default: 25, as lipsync render)")
    p.add_argument("--map", default=None, metavar="FILE", help="phoneme-to-viseme map (default: the shipped English one)")
    p.add_argument("--port", type=int, default=0, metavar="N", help="port on 127.0.0.1 (default: a free one)")
    p.add_argument("-o", "--output", default=None, metavar="OUT",
                   help="where saves go: OUT, or OUT with the saved format's extension (.TextGrid, .pgo, .tsv, "
                        ".json, .dat, .mp4 for a render) beside it (default: AUDIO's name + .edited)")
    p.add_argument("--open", action="store_true", help="open the page in the default browser")
    add_store_option(p)
    add_quiet_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..timing_editor import TimingEditor, make_app
    from ..web import Session, run as serve

    if not 0 <= args.port <= 65535:
        raise InputError(f"--port must be 0..65535, got {args.port}")
    session = Session.open("127.0.0.1", args.port)  # a taken port fails before any work
    try:
        editor = TimingEditor(args.audio, text=args.text, timeline=args.timeline, lang=args.lang, bank=args.bank,
                              fps=args.fps, out=args.output, store=args.store, quiet=args.quiet, map=args.map)
        app = make_app(editor, session)
        if args.open:
            import threading
            import webbrowser

            opener = threading.Timer(0.5, webbrowser.open, (session.url("/"),))
            opener.daemon = True
            opener.start()
        print(f"editing the timing of {args.audio}: saves go to {editor.out}.* (Ctrl-C to stop)", flush=True)
        serve(app, session, announce="lipsync edit-timeline: open")
    finally:
        session.close()
    return 0
