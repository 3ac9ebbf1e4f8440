"""Library calls from plain scripts (issue 19, item 1).

The documentation's Python examples (README.md and docs/*.md) are copied, as a new user
would, into a script *without*
``if __name__ == "__main__":`` and run in a fresh interpreter on a copy of the toon that has
no flows yet (no ``.lipsync/``). A library that starts a multiprocessing ``spawn`` pool
re-imports the caller's main module in every child: the script then runs again in each
child and the parent dies with ``BrokenProcessPool``. The scripts also count how many times
they were executed (a line appended to a file at the top of the script): exactly once.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The pages' headings above the embedding and live examples (docs/embed.md, docs/serve.md).
EMBEDDING = "Embed lipsync in an app"
LIVE = "Go live: LiveAnimator and `lipsync serve`"


def readme_examples():
    """The ```python blocks of README.md and docs/*.md, keyed by the heading they sit under
    (the first block under each heading). A shipped subject named in an example
    (``Bank.load("toon")``) is pointed at the test's copy without flows, ``visemes/toon``."""
    blocks = {}
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        heading, fence, body = "", None, []
        for line in page.read_text(encoding="utf-8").splitlines(keepends=True):
            if fence is None and line.startswith("```"):
                fence, body = line[3:].strip(), []
            elif fence is not None and line.startswith("```"):
                if fence == "python" and heading not in blocks:
                    blocks[heading] = "".join(body).replace('"toon"', '"visemes/toon"')
                fence = None
            elif fence is not None:
                body.append(line)
            elif line.startswith("#"):
                heading = line.lstrip("#").strip()
    return blocks


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A folder laid out like the repository for the README's relative paths, bank without flows."""
    d = tmp_path_factory.mktemp("plain")
    shutil.copytree(ROOT / "visemes" / "toon", d / "visemes" / "toon",
                    ignore=shutil.ignore_patterns(".lipsync"))
    assert not (d / "visemes" / "toon" / ".lipsync").exists()
    shutil.copytree(ROOT / "samples", d / "samples")
    (d / "tests" / "data" / "timelines").mkdir(parents=True)
    shutil.copy(ROOT / "tests/data/timelines/polly_mary_lamb.txt", d / "tests/data/timelines/")
    shutil.copy(ROOT / "tests/data/timelines/polly_mary_lamb.txt", d / "marks.txt")
    shutil.copy(ROOT / "samples" / "hello.wav", d / "speech.wav")
    return d


def run_plain(workdir: Path, name: str, body: str, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run ``body`` as a script with no main guard; it records each time it is executed."""
    runs = workdir / f"{name}.runs"
    runs.unlink(missing_ok=True)
    script = workdir / f"{name}.py"
    script.write_text(f"open({str(runs)!r}, 'a').write('ran\\n')\n" + body, encoding="utf-8")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, str(script)], cwd=workdir, capture_output=True, text=True,
                          timeout=timeout, env=env)
    assert proc.returncode == 0, f"{name} exited {proc.returncode}:\n{proc.stderr[-3000:]}"
    assert runs.read_text() == "ran\n", f"{name}: the script was executed {runs.read_text().count('ran')} times"
    return proc


def test_readme_has_the_examples():
    assert {EMBEDDING, LIVE} <= set(readme_examples())


def test_live_animator_example_as_a_plain_script(workdir):
    # The case: LiveAnimator on a bank with no flows computes all of them first.
    body = readme_examples()[LIVE] + textwrap.dedent("""
        assert frame.shape == (512, 512, 3) and frame.dtype.name == "uint8"
        print("stored", len(list((__import__("pathlib").Path("visemes/toon/.lipsync")).rglob("*.flow"))))
    """)
    proc = run_plain(workdir, "live", body)
    assert "stored 36" in proc.stdout


def test_embedding_example_as_a_plain_script(workdir):
    body = readme_examples()[EMBEDDING] + textwrap.dedent("""
        assert still.shape == (512, 512, 3) and half.shape == (512, 512, 3)
        print("frames", len(anim))
    """)
    proc = run_plain(workdir, "embed", body)
    assert re.search(r"frames \d+", proc.stdout)


def test_audio_example_as_a_plain_script(workdir):
    blocks = [b for h, b in readme_examples().items() if "Animator.from_audio" in b]
    assert len(blocks) == 1
    body = blocks[0] + textwrap.dedent("""
        print("words", anim.alignment.words.labels())
    """)
    proc = run_plain(workdir, "audio", body)
    assert "hello" in proc.stdout.lower()


def test_render_clip_and_server_from_a_plain_script(workdir, tmp_path):
    # The other library entry points that compute missing flows: render_clip and the live
    # server's app (which prepares its bank's flows when built).
    bank = tmp_path / "toon"
    shutil.copytree(workdir / "visemes" / "toon", bank, ignore=shutil.ignore_patterns(".lipsync"))
    body = textwrap.dedent(f"""
        from lipsync.pipeline.clip import render_clip
        render_clip("samples/hello.phn", {str(tmp_path / 'out.mp4')!r}, bank={str(bank)!r}, quiet=True)
        import os
        assert os.path.getsize({str(tmp_path / 'out.mp4')!r}) > 1000
        import shutil
        shutil.rmtree({str(bank / '.lipsync')!r})
        from lipsync.server import LiveServer, ServeConfig
        from lipsync.web import Session
        server = LiveServer(ServeConfig(bank={str(bank)!r}), session=Session.open())
        server.close()
        print("stored", len(list(__import__("pathlib").Path({str(bank / '.lipsync')!r}).rglob("*.flow"))))
    """)
    assert "stored 36" in run_plain(workdir, "clip", body).stdout


def test_run_batch_from_a_plain_script(workdir, tmp_path):
    # lipsync.batch.run_batch starts a local dask cluster: its workers must not re-run the
    # script (a LocalCluster's nannies spawn them by re-importing __main__).
    (tmp_path / "a.tsv").write_text("0.00\tX\n0.40\tD\n0.80\tX\n")
    (tmp_path / "m.csv").write_text("input,output\na.tsv,a.mp4\n")
    body = textwrap.dedent(f"""
        from lipsync.batch import run_batch
        report = run_batch({str(tmp_path / 'm.csv')!r}, {str(tmp_path / 'out')!r}, workers=2,
                           cache={str(tmp_path / 'cache')!r}, quiet=True)
        print(report.summary())
        assert report.done == 1, report.clips
    """)
    run_plain(workdir, "batch", body)
    assert (tmp_path / "out" / "a.mp4").stat().st_size > 1000
