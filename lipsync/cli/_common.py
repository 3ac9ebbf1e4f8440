"""Options and helpers that several commands share, so each is defined once.

* :func:`add_timeline_options`: how a timeline file is read and mapped (``render``,
  ``timeline``, ``cues``, ...). ``--format`` is left to the commands (their output format),
  so the input format option is ``--timeline-format``. A Moho ``.dat`` file counts in
  frames of its own rate, given with ``--moho-fps`` (default 24), kept apart from ``--fps``
  because the file's rate and the output rate are independent.
* :func:`load_viseme_timeline`: reading, mapping and checking against a bank.
* :func:`add_bank_option`, :func:`add_store_option`, :func:`add_jobs_option`,
  :func:`add_quiet_option`: the subject, its flow store, worker processes, progress bars.
"""

from __future__ import annotations

import argparse
import os
from typing import Iterable, Optional, Tuple

from ..phonetics.phonemes import DEFAULT_MAP, MAPS, PhonemeMap, bank_viseme_timeline, load_map
from ..readers import READERS, read_timeline
from ..motion.timeline import Timeline
from ..motion.timing import DEFAULT_CURVE, timing_names

DEFAULT_MOHO_FPS = 24.0


#: argparse attributes that name a command's input files (a list for nargs options); a
#: ``text`` or ``map`` counts when it names a file. ``bank`` folders are inputs as wholes.
_INPUT_ARGS = ("timeline", "timelines", "audio", "video", "text", "video_text", "map", "manifest", "atlas", "folder")
_BANK_ARGS = ("bank", "bank_option")
#: Inputs that must be files: ffmpeg seeks in media and reads it more than once, and a
#: transcript is read whole (timelines may come from a pipe: their readers bound the size).
_FILE_ONLY_ARGS = ("audio", "video", "text", "video_text")
#: the attribute naming a command's output, and the files a command writes beside it
_OUTPUT_ARG = "output"
_BESIDE_OUTPUT = {"atlas": (".json",)}


def check_outputs_apart(args: argparse.Namespace) -> None:
    """Refuse (InputError, exit 2) an output that is one of the command's inputs, before any work.

    Every command that writes goes through here (``lipsync.cli.main`` calls it): the output,
    and what the command writes beside it, against every input file and the bank's folder,
    by inode (:func:`lipsync._files.refuse_output_over_input`).

    Examples
    --------
    >>> import argparse, os, tempfile
    >>> d = tempfile.mkdtemp(); p = os.path.join(d, "a.phn"); _ = open(p, "w").write("0 1 aa")
    >>> check_outputs_apart(argparse.Namespace(timeline=p, output=os.path.join(d, "a.mp4")))
    >>> check_outputs_apart(argparse.Namespace(timeline=p, output=p))   # doctest: +ELLIPSIS
    Traceback (most recent call last):
    lipsync.errors.InputError: ...a.phn: is the input ...a.phn (the same file); write the output to another name
    """
    from .._files import refuse_output_over_input

    inputs = []
    for name in _INPUT_ARGS:
        value = getattr(args, name, None)
        for v in value if isinstance(value, (list, tuple)) else [value]:
            if isinstance(v, str) and v and len(v) < 4096 and "\0" not in v:
                inputs.append(v)
    for name in _FILE_ONLY_ARGS:
        value = getattr(args, name, None)
        for v in value if isinstance(value, (list, tuple)) else [value]:
            if isinstance(v, str) and v in inputs:
                _refuse_special_file(v)
    out = getattr(args, _OUTPUT_ARG, None)
    if not isinstance(out, str) or not out:
        return
    _check_writable(out)
    outputs = [out] + [os.path.splitext(out)[0] + ext for ext in _BESIDE_OUTPUT.get(getattr(args, "command", ""), ())]
    banks = [getattr(args, name, None) for name in _BANK_ARGS]
    inputs += [b for b in banks if isinstance(b, str) and os.path.isfile(b)]   # atlas's first positional
    refuse_output_over_input(outputs, inputs, folders=[b for b in banks if isinstance(b, str)])


#: Where a path names a device or a process's stream rather than a file: ``--audio
#: /dev/stdin`` passed the "is a file" check (a redirected stdin is a link to the file) and
#: then failed inside ffmpeg with exit 1 and its raw log (issue 38).
_SPECIAL_ROOTS = ("/dev/", "/proc/")
#: Characters the temporary name adds to OUT's (``.OUT.partial-PID-XXXXXXXX.ext``, lipsync._files).
_PARTIAL_NAME_EXTRA = 32


def _refuse_special_file(path: str) -> None:
    from ..errors import InputError

    if not os.path.exists(path):
        return
    real = os.path.realpath(path)
    if any(p.startswith(_SPECIAL_ROOTS) for p in (os.path.abspath(path), real)) or not (
            os.path.isfile(real) or os.path.isdir(real)):
        raise InputError("is a device, pipe or stream, not a file: save the data to a file and give its name",
                         path=path)


def _check_writable(out: str) -> None:
    """The output's folder exists and takes a file of that name (exit 2 naming OUT, not errno text at the end)."""
    from ..errors import InputError

    folder = os.path.dirname(os.path.abspath(out)) or "."
    if not os.path.isdir(folder):
        return   # the commands say so themselves (some make the folder)
    try:
        name_max = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    if len(os.fsencode(os.path.basename(out))) + _PARTIAL_NAME_EXTRA > name_max:
        raise InputError(f"the file name is too long ({len(os.path.basename(out))} characters; at most "
                         f"{name_max - _PARTIAL_NAME_EXTRA} here)", path=out)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"cannot write here: the folder {folder} is not writable", path=out)
    import tempfile

    try:   # a read-only file system says so only when written to (os.access is True for root)
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".lipsync-probe-")
    except OSError as exc:
        raise InputError(f"cannot write here: the folder {folder} is not writable ({exc.strerror or exc})",
                         path=out) from None
    os.close(fd)
    os.unlink(probe)


def add_bank_option(parser: argparse.ArgumentParser) -> None:
    """``--bank DIR_OR_NAME``: the subject (default: the shipped toon)."""
    parser.add_argument("--bank", default=None, metavar="DIR_OR_NAME",
                        help="viseme bank folder, or a shipped subject's name: toon (the default), grid-s1")


def add_mismatch_option(parser) -> None:
    """``--allow-mismatch``: go on with a transcript that does not fit the speech at all.

    Without it such a transcript (the aligner's confidence below
    ``lipsync.speech.align.NO_FIT_CONFIDENCE``) stops the command with exit 2: it is almost
    always the wrong file, and a video of recognised words would hide that.
    """
    parser.add_argument("--allow-mismatch", action="store_true",
                        help="go on when the --text transcript does not fit the speech at all (default: exit 2)")


def add_shapes_option(parser) -> None:
    """``--shapes all|basic``: keep to Rhubarb's basic shapes A-F (and X)."""
    parser.add_argument("--shapes", choices=("all", "basic"), default="all",
                        help="mouth shapes used: all of the map's (default), or basic: Rhubarb's A-F and X, "
                             "G shown as B and H as C (Rhubarb's fallbacks), for a character drawn without G and H")


def shaped_timeline(args, *, rest=None, viseme_names=None):
    """``load_viseme_timeline`` then ``--shapes``: (viseme timeline, map) in the bank's names."""
    from ..writers.rhubarb import basic_shapes_track

    timeline, pmap = load_viseme_timeline(args, rest=rest, viseme_names=viseme_names)
    base = load_map(getattr(args, "map", None) or DEFAULT_MAP)
    return basic_shapes_track(timeline, pmap, base, args.shapes), pmap


def add_store_option(parser: argparse.ArgumentParser) -> None:
    """``--store DIR``: where the bank's flows are cached."""
    parser.add_argument("--store", default=None, metavar="DIR", help="flow store folder (default: BANK/.lipsync)")


def add_jobs_option(parser: argparse.ArgumentParser, what: str = "preprocessing") -> None:
    """``--jobs N``: threads computing flows."""
    parser.add_argument("--jobs", "-j", type=int, default=None, metavar="N",
                        help=f"threads for {what} (default: all cores)")


def add_quiet_option(parser: argparse.ArgumentParser) -> None:
    """``--quiet``: no progress bars or summary."""
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress bars or summary")


def lang_code(value: str) -> str:
    """argparse type of ``--lang``: an English tag as given, any other checked against espeak-ng's.

    An unknown code (or a missing espeak-ng extra) stops the command before any work, with
    exit 2 and the list of codes.
    """
    from ..errors import InputError
    from ..phonetics.g2p import is_english, resolve

    if not is_english(value):
        try:
            resolve(value)
        except InputError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    return value


#: --lang's help, shared by every command that has the option.
LANG_HELP = ("language of the speech and transcript, as a BCP 47 tag (fr, pt-BR, zh, ru, ...); default "
             "English. Other languages need the optional espeak-ng extra (pip install 'lipsync[lang]', "
             "GPL-3): words to IPA by espeak-ng, aligned with the closest English sounds; phones in IPA")


def add_lang_option(parser) -> None:
    """``--lang CODE``: the language of audio input and its transcript."""
    parser.add_argument("--lang", type=lang_code, default=None, metavar="CODE", help=LANG_HELP)


def check_png(path: str) -> None:
    """Refuse an output name that is not a .png (before any work is done)."""
    from ..errors import InputError

    if not path.lower().endswith(".png"):
        raise InputError(f"output must be a .png file, got {path!r}")


#: --timing's help, shared by every command that has the option.
TIMING_HELP = (f"how the mouth moves: a transition curve of the rule-based sequencer "
               f"({', '.join(n for n in timing_names() if n != 'dominance')}) or 'dominance' "
               f"(coarticulation fitted to real speech); default: the bank's 'timing' in bank.yaml, "
               f"else {DEFAULT_CURVE}")


def add_timeline_options(parser: argparse.ArgumentParser) -> None:
    """Add --timeline-format, --tier, --sample-rate, --moho-fps, --text, --lang, --map and --timing to ``parser``."""
    group = parser.add_argument_group("timeline input")
    group.add_argument("--timeline-format", choices=READERS.names(), default=None, metavar="NAME",
                       help="input timeline format (default: from the extension, then the content); "
                            f"one of: {', '.join(READERS.names())}")
    group.add_argument("--tier", default=None, metavar="NAME",
                       help="TextGrid tier to read (default: phones), or Papagayo .pgo voice "
                            "(default: the first)")
    group.add_argument("--sample-rate", type=float, default=16000, metavar="N",
                       help="samples per second of TIMIT .phn times (default: 16000)")
    group.add_argument("--moho-fps", type=float, default=DEFAULT_MOHO_FPS, metavar="N",
                       help="frame rate a Moho .dat file was written at (default: 24)")
    group.add_argument("--text", default=None, metavar="TEXT_OR_FILE",
                       help="for audio input: its transcript, or a text file holding it "
                            "(default: the words are recognised)")
    add_mismatch_option(group)
    add_lang_option(group)
    group.add_argument("--map", default=DEFAULT_MAP, metavar="NAME_OR_FILE",
                       help=f"phoneme-to-viseme map: a shipped name ({', '.join(MAPS.names())}) "
                            f"or a YAML file (default: {DEFAULT_MAP})")
    group.add_argument("--timing", choices=timing_names(), default=None, metavar="NAME",
                       help=TIMING_HELP)


def load_viseme_timeline(args: argparse.Namespace, *, rest: Optional[str] = None,
                         viseme_names: Optional[Iterable[str]] = None) -> Tuple[Timeline, PhonemeMap]:
    """Read ``args.timeline``, map it to visemes and check the map against a bank.

    Parameters
    ----------
    args : argparse.Namespace
        With ``timeline`` (the file) and the options of :func:`add_timeline_options`.
    rest : str, optional
        The bank's rest viseme, shown for silence (default: the map's silence viseme).
    viseme_names : iterable of str, optional
        The bank's viseme names. When given, the map's visemes are matched to them (through
        the map's aliases where needed, e.g. Preston Blair names) and a map viseme the bank
        lacks is a MapError.

    Returns
    -------
    (Timeline, PhonemeMap)
        The viseme timeline in the bank's viseme names, and the map renamed to them (its
        ``closures`` are what :func:`lipsync.motion.sequencer.sequence` wants).

    Examples
    --------
    >>> import argparse, os, tempfile
    >>> p = os.path.join(tempfile.mkdtemp(), "a.phn")
    >>> _ = open(p, "w").write("0 1600 h#\\n1600 3200 m\\n3200 6400 aa\\n")
    >>> parser = argparse.ArgumentParser()
    >>> _ = parser.add_argument("timeline")
    >>> add_timeline_options(parser)
    >>> tl, pmap = load_viseme_timeline(parser.parse_args([p]), rest="X")
    >>> tl.labels(), pmap.closures
    (['X', 'A', 'D'], ['A'])
    """
    pmap = load_map(getattr(args, "map", None) or DEFAULT_MAP)
    timeline = read_timeline(args.timeline, getattr(args, "timeline_format", None),
                             tier=getattr(args, "tier", None),
                             sample_rate=getattr(args, "sample_rate", 16000),
                             fps=getattr(args, "moho_fps", DEFAULT_MOHO_FPS),
                             text=getattr(args, "text", None), quiet=getattr(args, "quiet", True),
                             lang=getattr(args, "lang", None))
    map_arg = str(getattr(args, "map", None) or "")
    return bank_viseme_timeline(timeline, pmap, viseme_names, rest=rest,
                                map_path=map_arg if os.path.isfile(map_arg) else None)
