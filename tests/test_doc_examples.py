"""Every example of the README and the documentation, run as a user would run it.

The package is built into a wheel once (``pip wheel --no-deps``) and installed into a
folder of its own; every example then runs from a plain script in a temporary folder with
only that folder on ``PYTHONPATH`` -- nothing of the repository is importable, and the
scripts check that ``lipsync`` really is the installed copy. What the examples read is laid
out in the temporary folder as a user would have it: the repository's ``samples/``, and the
generic names the pages use (``speech.wav``, ``script.phn``, ...) made from the samples and
the tests' real files (:data:`FIXTURES`).

* Shell blocks (```sh): each line starting with ``lipsync`` runs, in page order, through
  ``lipsync.cli.main`` of the installed copy in one process (exit code 0, and every ``-o``
  output exists afterwards). Other lines (``cd``, ``python3 -m http.server``) are prose.
* Python blocks (```python): each runs as its own script.
* A block that must not run (a server that runs until stopped, a cluster, the reader's own
  video) carries ``<!-- doc-test: skip (why) -->`` on the line before it; there are few.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import textwrap
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SKIP = re.compile(r"<!-- doc-test: skip \((?P<why>[^)]+)\) -->")
#: At most this many blocks may be skipped (servers, clusters, the reader's own video).
MAX_SKIPPED = 13  # +1: lipsync edit-timeline serves until stopped

#: The example files the pages name -> where the test takes them from.
FIXTURES = {
    "speech.wav": "samples/hello.wav", "talk.wav": "samples/hello.wav", "script.wav": "samples/hello.wav",
    "words.wav": "samples/hello.wav", "scene.wav": "samples/hello.wav",
    "speech.txt": "samples/hello.lab", "script.txt": "samples/hello.lab",
    "speech.TextGrid": "samples/hello.TextGrid", "words.TextGrid": "samples/hello.TextGrid",
    "other-line.TextGrid": "samples/balloons.TextGrid", "script.phn": "samples/hello.phn",
    "cues.tsv": "tests/data/timelines/rhubarb_cues.tsv",
    "marks.txt": "tests/data/timelines/polly_mary_lamb.txt",
    "words.json": "tests/data/timelines/whisper_timestamped_apollo11.json",
    "scene.pgo": "tests/data/timelines/papagayo_two_voices.pgo",
    "face.jpg": "tests/data/faces/astronaut.jpg",
    "speaker.mp4": "tests/data/grid-s1/bbwm5s.mpg",
    "french.TextGrid": "tests/data/phonetics/french_mfa_ipa.TextGrid",
    "french.ogg": "tests/data/languages/fleurs-fr-004.ogg", "french.txt": "tests/data/languages/fleurs-fr-004.txt",
    "talk.mp4": "tests/data/grid-s1/bbwm5s.mpg", "new-speech.wav": "samples/balloons.wav",
    "new-speech.txt": "samples/balloons.lab",
    "spanish.opus": "tests/data/languages/mls-es-13697_11991_000000.opus",
    "spanish.txt": "tests/data/languages/mls-es-13697_11991_000000.txt",
}
#: Made from samples/hello.wav by the bundled ffmpeg (the pages show other containers).
CONVERTED = ("speech.mp3", "speech.m4a", "speech.flac")


def doc_files():
    return [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))


def doc_blocks():
    """(file, line, language, code, reason to skip or None) of every fenced block."""
    for path in doc_files():
        lines = path.read_text(encoding="utf-8").splitlines()
        fence, prev, body, start = None, "", [], 0
        for i, line in enumerate(lines):
            if fence is None and line.startswith("```"):
                fence, body, start = line[3:].strip(), [], i + 1
                mark = SKIP.search(prev)
                skip = mark.group("why") if mark else None
            elif fence is not None and line.startswith("```"):
                yield path.relative_to(ROOT).as_posix(), start, fence, "\n".join(body) + "\n", skip
                fence = None
            elif fence is not None:
                body.append(line)
            if line.strip():
                prev = line


def shell_commands(code: str):
    for line in code.splitlines():
        if line.strip().startswith("lipsync "):
            yield shlex.split(line, comments=True)[1:]


def test_the_pages_have_examples_and_few_are_skipped():
    blocks = list(doc_blocks())
    skipped = [(f, n, why) for f, n, lang, _, why in blocks if why and lang in ("sh", "python")]
    runnable = [b for b in blocks if not b[4] and b[2] in ("sh", "python")]
    assert len(runnable) >= 25, len(runnable)
    assert len(skipped) <= MAX_SKIPPED, skipped
    # a skip marker stands right before a block (a stray one would silently skip nothing)
    for path in doc_files():
        text = path.read_text(encoding="utf-8")
        for m in SKIP.finditer(text):
            assert text[m.end():].lstrip("\n").startswith("```"), f"{path}: a skip marker not before a block"


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """The package built as a wheel and installed into a folder of its own (the site)."""
    tmp = tmp_path_factory.mktemp("wheel")
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp / "dist"),
                            str(ROOT)], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr[-3000:]
    wheel = next((tmp / "dist").glob("lipsync-*.whl"))
    site = tmp / "site"
    inst = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-compile",
                           "--target", str(site), str(wheel)], capture_output=True, text=True)
    assert inst.returncode == 0, inst.stderr[-3000:]
    # The shipped subjects' flows, once, before the examples (which would otherwise compute
    # them at the same time in several processes): a user computes them once too.
    for subject in ("toon", "grid-s1"):
        pre = _run([sys.executable, "-m", "lipsync", "preprocess", subject, "-q"], tmp, site)
        assert pre.returncode == 0, pre.stderr[-2000:]
    return site


@pytest.fixture(scope="module")
def sandbox(tmp_path_factory, installed):
    """A user's folder: samples/, the example files, a subject folder, drawings, sprites."""
    import cv2
    import imageio_ffmpeg
    import numpy as np

    d = tmp_path_factory.mktemp("user")
    shutil.copytree(ROOT / "samples", d / "samples")
    for name, src in FIXTURES.items():
        shutil.copy(ROOT / src, d / name)
    # a page's YAML file example (a block starting "# NAME.yaml") is the file its commands use
    for _, _, lang, code, _ in doc_blocks():
        first = code.split("\n", 1)[0]
        if lang == "yaml" and first.startswith("# ") and first.endswith(".yaml") and "/" not in first:
            (d / first[2:]).write_text(code, encoding="utf-8")
    for name in CONVERTED:
        subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-loglevel", "error", "-i", str(ROOT / "samples/hello.wav"),
                        str(d / name)], check=True)
    toon = ROOT / "visemes" / "toon"
    # visemes/mine: the toon's copy, with the installed toon's flows (the store is keyed by
    # content, so they are this bank's flows too)
    shutil.copytree(toon, d / "visemes" / "mine", ignore=shutil.ignore_patterns(".lipsync"))
    shutil.copytree(installed / "lipsync" / "_visemes" / "toon" / ".lipsync", d / "visemes" / "mine" / ".lipsync")
    # drawn/: nine drawings without bank.yaml; visemes/sprites: the toon cut out (RGBA).
    # Both at 128 px, so that their flows cost a sixteenth of the toon's.
    (d / "drawn").mkdir()
    sprites = d / "visemes" / "sprites"
    sprites.mkdir(parents=True)
    _scaled_bank(toon, sprites, SMALL)
    alpha = np.zeros((SMALL, SMALL), np.uint8)
    cv2.ellipse(alpha, (SMALL // 2, SMALL * 300 // 512), (SMALL * 200 // 512, SMALL * 230 // 512), 0, 0, 360, 255, -1)
    for png in sorted(sprites.glob("*.png")):
        img = cv2.imread(str(png))
        cv2.imwrite(str(d / "drawn" / f"mouth_{png.stem}.png"), img)
        cv2.imwrite(str(png), np.dstack([img, alpha]))
    return d


#: Side of the small banks the examples make (the toon is 512).
SMALL = 128


def _scaled_bank(src: Path, dst: Path, size: int) -> None:
    """``src`` (a square bank) resized to ``size`` px, its lines moved with the pixels
    (pixel centres at integers: x' = (x + 0.5) * s - 0.5)."""
    import cv2
    import yaml

    doc = yaml.safe_load((src / "bank.yaml").read_text())
    s = size / cv2.imread(str(src / doc["visemes"][doc["rest"]]["image"])).shape[1]

    def scale(v):
        if isinstance(v, list) and len(v) == 2 and all(isinstance(c, (int, float)) for c in v):
            return [round((c + 0.5) * s - 0.5, 3) for c in v]
        return [scale(x) for x in v] if isinstance(v, list) else v

    for viseme in doc["visemes"].values():
        viseme["lines"] = {k: scale(v) for k, v in viseme["lines"].items()}
        img = cv2.imread(str(src / viseme["image"]))
        cv2.imwrite(str(dst / viseme["image"]), cv2.resize(img, (size, size), interpolation=cv2.INTER_AREA))
    (dst / "bank.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))


DRIVER = textwrap.dedent("""
    import json, os, sys, time, warnings
    import lipsync
    site = os.environ["DOC_TEST_SITE"]
    assert os.path.realpath(lipsync.__file__).startswith(os.path.realpath(site)), lipsync.__file__
    from lipsync.cli import main
    results = []
    for where, argv in json.load(open("commands.json")):
        warnings.resetwarnings()
        t0 = time.process_time()
        code = main(argv)
        print(f"{time.process_time() - t0:6.2f} s CPU  {where}  lipsync {' '.join(argv)}", file=sys.stderr)
        outs = [argv[i + 1] for i, a in enumerate(argv[:-1]) if a in ("-o", "--output")]
        results.append([where, argv, code, [o for o in outs if not os.path.exists(o)]])
    json.dump(results, open("results.json", "w"))
""")

PREAMBLE = textwrap.dedent("""
    import os as _os, lipsync as _l
    assert _os.path.realpath(_l.__file__).startswith(_os.path.realpath(_os.environ["DOC_TEST_SITE"])), _l.__file__
""")


def _run(args, cwd, site, timeout=300):
    import resource
    import time

    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(PYTHONPATH=str(site), DOC_TEST_SITE=str(site), PYTHONDONTWRITEBYTECODE="1")
    t0 = time.perf_counter()
    proc = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    print(f"{time.perf_counter() - t0:6.1f} s wall  {' '.join(args[1:])}")
    return proc


def test_every_example_runs_against_the_installed_wheel(installed, sandbox):
    commands, scripts = [], []
    for file, line, lang, code, skip in doc_blocks():
        if skip:
            continue
        if lang == "sh":
            commands += [(f"{file}:{line}", argv) for argv in shell_commands(code)]
        elif lang == "python":
            scripts.append((f"{file}:{line}", code))
    assert len(commands) >= 40 and len(scripts) >= 6
    (sandbox / "commands.json").write_text(json.dumps(commands))
    (sandbox / "driver.py").write_text(DRIVER)
    jobs = [("shell examples", [sys.executable, "driver.py"])]
    for i, (where, code) in enumerate(scripts):
        (sandbox / f"example_{i}.py").write_text(PREAMBLE + code, encoding="utf-8")
        jobs.append((where, [sys.executable, f"example_{i}.py"]))
    with ThreadPoolExecutor(2) as pool:  # two cores: the shell examples beside the scripts
        done = list(pool.map(lambda job: (job[0], _run(job[1], sandbox, installed)), jobs))
    failed = [f"{where}: exit {p.returncode}\n{p.stderr[-1500:]}" for where, p in done if p.returncode != 0]
    assert not failed, "\n\n".join(failed)
    results = json.loads((sandbox / "results.json").read_text())
    bad = [f"{where}: lipsync {' '.join(argv)} -> exit {code}, missing {missing}"
           for where, argv, code, missing in results if code != 0 or missing]
    assert not bad, "\n".join(bad) + "\n" + done[0][1].stderr[-3000:]
    assert len(results) == len(commands)
    print("\n".join(sorted(done[0][1].stderr.splitlines(), reverse=True)[:15]))
