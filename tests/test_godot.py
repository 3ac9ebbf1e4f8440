"""The Godot player script (lipsync/atlas/static/lipsync_player.gd) in Godot 3's headless server.

A tiny project made here holds the script, an atlas and frames.json of samples/hello.phn
made by lipsync, and the speech; tests/data/godot/check.gd (a SceneTree script) asks the
player for chosen times, then lets it play the speech and records the time and cell its
``_process`` shows on the audio clock. Both are compared with frames.json by the schema's
rule, written here: at time t the cell is ``frames[clamp(floor(t * fps), 0, count - 1)]``.

Skipped (with the reason) when Debian's ``godot3-server`` is absent (``apt-get install
godot3-server``).
"""

import json
import math
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from lipsync.cli import main

GODOT = shutil.which("godot3-server")
pytestmark = pytest.mark.skipif(GODOT is None, reason="no Godot 3 server: apt-get install godot3-server")

ROOT = Path(__file__).resolve().parents[1]
HELLO = ROOT / "samples" / "hello.phn"


def _printed(out, tag):
    return json.loads(next(line for line in out.splitlines() if line.startswith(tag + " "))[len(tag) + 1:])


@pytest.fixture(scope="module")
def godot(tmp_path_factory):
    import synthetic

    tmp = tmp_path_factory.mktemp("godot")
    bank = synthetic.write_bank(tmp / "bank", synthetic.RHUBARB_SHAPES)
    proj = tmp / "project"
    mouth = proj / "mouth"
    assert main(["atlas", str(bank), "-o", str(mouth / "mouth.png"), str(HELLO), "-q", "--store",
                 str(tmp / "store"), "--player"]) == 0
    assert main(["cues", str(HELLO), "--format", "atlas", "--atlas", str(mouth / "mouth.json"), "--fps", "30",
                 "--bank", str(bank), "-o", str(mouth / "hello.frames.json")]) == 0
    doc = json.loads((mouth / "hello.frames.json").read_text())
    # mid-frame times, exact frame starts, before the start and after the end
    times = [(k + 0.5) / 30 for k in range(0, doc["count"], 7)] + [k / 30 for k in (3, 17, 40)] + [-1.0, 99.0]
    (proj / "project.godot").write_text('config_version=4\n\n[application]\nconfig/name="lipsync player check"\n')
    shutil.copy(mouth / "lipsync_player.gd", proj / "lipsync_player.gd")  # --player wrote it beside the atlas
    shutil.copy(ROOT / "tests" / "data" / "godot" / "check.gd", proj / "check.gd")
    shutil.copy(ROOT / "samples" / "hello.wav", proj / "hello.wav")
    (proj / "times.json").write_text(json.dumps(times))
    env = {**os.environ, "HOME": str(tmp), "XDG_DATA_HOME": str(tmp / "data"), "XDG_CONFIG_HOME": str(tmp / "config")}
    proc = subprocess.run([GODOT, "--no-window", "--path", str(proj), "-s", "check.gd"], capture_output=True,
                          text=True, env=env, timeout=120)
    assert proc.returncode == 0 and "LIPSYNC " in proc.stdout, (proc.stdout + proc.stderr)[-3000:]
    atlas = json.loads((mouth / "mouth.json").read_text())
    return atlas, doc, times, _printed(proc.stdout, "LIPSYNC"), _printed(proc.stdout, "CLOCKED")


def _cell(doc, t):
    return doc["frames"][min(max(math.floor(t * doc["fps"]), 0), doc["count"] - 1)]


def test_the_player_shows_frames_jsons_cell_at_chosen_times(godot):
    atlas, doc, times, shown, _ = godot
    assert [s["t"] for s in shown["shown"]] == pytest.approx(times, abs=1e-6)  # printed to 6 decimals
    for t, s in zip(times, shown["shown"]):
        cell = _cell(doc, t)
        assert s["cell"] == cell, s
        assert s["rect"] == atlas["cells"][cell]["rect"]  # the region of the texture drawn
    assert len({s["cell"] for s in shown["shown"]}) > 5
    assert shown["mouth_pos"] == atlas["region"][:2] and shown["mouth_scale"] == [1, 1]
    assert shown["texture"] == atlas["image_size"] and shown["base"] == atlas["frame_size"]
    assert shown["stream_seconds"] == pytest.approx(doc["duration"], abs=1e-3)


def test_the_player_follows_the_audio_clock(godot):
    _, doc, _, _, clocked = godot
    assert len(clocked) > 20, clocked  # the speech played in the server (its dummy audio driver mixes)
    for c in clocked:
        assert c["cell"] == _cell(doc, c["time"]), c
    times = [c["time"] for c in clocked]
    assert max(times) > 0.8 * doc["duration"]  # it played through most of the line
    assert len({c["cell"] for c in clocked}) > 10
