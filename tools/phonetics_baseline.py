"""Record the viseme cues today's English maps give for every timeline in tests/data and samples/.

Run once on main before issue 29 changed the maps (commit 1e75df3):

    .venv/bin/python tools/phonetics_baseline.py tests/data/phonetics/english_cues.json

tests/test_phonetics.py maps the same files with the current code and requires the same
cues. Audio inputs are left out (they would be aligned, which is another stage's business);
files that are errors by design (error_*) are left out.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SOURCES = ("tests/data/timelines", "tests/data/conformance", "tests/data/cues", "samples")
AUDIO = (".wav", ".flac", ".mp3", ".ogg", ".opus", ".mpg", ".mp4")
MAPS = ("english-to-rhubarb", "english-to-oculus")


def timeline_files():
    for src in SOURCES:
        for path in sorted((ROOT / src).rglob("*")):
            name = path.name
            if (not path.is_file() or name.startswith("error_") or name.endswith((".expected", ".error", ".md"))
                    or name.lower().endswith(AUDIO) or name in ("LICENSE",) or path.suffix == ".txt"
                    and "polly" not in name and "audacity" not in name):
                continue
            yield path


def cues(path: Path):
    from lipsync.phonetics.phonemes import load_map, map_timeline
    from lipsync.readers import read_timeline

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tl = read_timeline(str(path))
    except Exception:  # noqa: BLE001 - not a timeline on its own (a transcript, a manifest)
        return None
    out = {"kind": tl.kind}
    for name in MAPS:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            vt = map_timeline(tl, load_map(name))
        out[name] = [[round(s.start, 9), round(s.end, 9), s.label] for s in vt]
        out[name + ":warnings"] = sorted({str(w.message).split(": label ")[-1].split(" is not")[0] for w in caught})
    return out


def main(argv):
    result = {}
    for path in timeline_files():
        got = cues(path)
        if got is not None:
            result[str(path.relative_to(ROOT))] = got
    # Every label the English phone set knows (ARPAbet with and without stress, TIMIT, MFA's
    # English IPA), one at a time, through both maps.
    from lipsync.phonetics.phonemes import load_map, load_phoneset

    ps = load_phoneset("english")
    labels = sorted(set(ps.phones) | set(ps.aliases) | {p + d for p in ps.phones for d in "012"}
                    | {p.lower() for p in ps.phones})
    result["labels"] = {name: {lab: load_map(name).targets(lab) for lab in labels} for name in MAPS}
    Path(argv[1]).parent.mkdir(parents=True, exist_ok=True)
    Path(argv[1]).write_text(json.dumps(result, ensure_ascii=False, indent=None, separators=(",", ":")) + "\n",
                             encoding="utf-8")
    print(f"{len(result)} timelines -> {argv[1]}")


if __name__ == "__main__":
    main(sys.argv)
