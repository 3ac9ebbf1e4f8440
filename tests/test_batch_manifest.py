"""``lipsync batch`` without a cluster: manifest checks, clip keys, sidecars, bank packs."""

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import synthetic
from lipsync.batch import ManifestError, clip_key, local_bank, pack_bank, read_manifest
from lipsync.batch.bankpack import install_entries
from lipsync.batch.sidecar import read_done, sidecar_path, write_done
from lipsync.banks.bank import Bank
from lipsync.cli import main


@pytest.fixture()
def folder(tmp_path, synthetic_bank_dir):
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "a.tsv").write_text("0.00\tX\n0.40\tO\n0.80\tX\n")
    (tmp_path / "in" / "b.phn").write_text("0 1600 h#\n1600 6400 aa\n6400 8000 h#\n")
    return tmp_path


def write(path, text):
    path.write_text(text)
    return path


def test_csv_and_json_lines_give_the_same_jobs_with_paths_relative_to_the_manifest(folder, synthetic_bank_dir,
                                                                                     monkeypatch):
    bank = os.path.relpath(synthetic_bank_dir, folder)
    csv = write(folder / "m.csv", "input,output,bank,fps,timing,method\n"
                                  f"in/a.tsv,x/one.mp4,{bank},30,linear,dissolve\n"
                                  "\n"                                    # blank lines are skipped
                                  f"in/b.phn,two.mov,{bank},,,\n")
    jsonl = write(folder / "m.jsonl",
                  json.dumps({"input": "in/a.tsv", "output": "x/one.mp4", "bank": bank, "fps": 30,
                              "timing": "linear", "method": "dissolve"}) + "\n\n"
                  + json.dumps({"input": "in/b.phn", "output": "two.mov", "bank": bank}) + "\n")
    monkeypatch.chdir("/")  # relative to the manifest, not to the working folder
    a, b = read_manifest(csv), read_manifest(jsonl)
    assert [j.line for j in a] == [2, 4] and [j.line for j in b] == [1, 3]
    strip = [(j.input, j.output, j.bank, j.fps, j.timing, j.method, j.map) for j in a]
    assert strip == [(j.input, j.output, j.bank, j.fps, j.timing, j.method, j.map) for j in b]
    assert a[0].input == folder / "in" / "a.tsv" and a[0].bank == Path(synthetic_bank_dir).resolve()
    # no timing given: "" is the bank's own (bank.yaml's timing, else the default curve)
    assert (a[0].fps, a[1].fps, a[1].method, a[1].timing) == (30.0, 25.0, "flow", "")


def test_every_bad_row_is_reported_with_its_line_before_anything_runs(folder, synthetic_bank_dir, capsys):
    (folder / "out").mkdir()
    os.symlink(folder, folder / "out" / "link")  # a symbolic link in OUTDIR that leads out of it
    rows = [
        "input,output,bank,fps,map,method",
        "in/a.tsv,ok.mp4,,,,",                      # 2: fine
        "in/a.tsv,../up.mp4,,,,",                   # 3: escapes
        "in/a.tsv,/abs.mp4,,,,",                    # 4: absolute
        "in/missing.tsv,m.mp4,,,,",                 # 5: no input
        "in/a.tsv,ok.mp4,,,,",                      # 6: duplicate output
        "in/a.tsv,f.mp4,,500,,",                    # 7: fps out of range
        "in/a.tsv,g.mp4,,,no-such-map,",            # 8: map
        "in/a.tsv,h.mp4,,,,warp",                   # 9: method
        "in/a.tsv,i.mp4,nobank,,,",                 # 10: bank folder without bank.yaml
        "in/a.tsv,frames/,,,,",                     # 11: a folder (PNG frames), not a video file
        "in/a.tsv,link/x.mp4,,,,",                  # 12: through the symbolic link
        "in/a.tsv,j.mp4.lipsync.json,,,,",          # 13: the sidecar suffix
        "in/a.tsv,a/b/../../../k.mp4,,,,",          # 14: escapes after normalising
    ]
    manifest = write(folder / "m.csv", "\n".join(rows) + "\n")
    (folder / "nobank").mkdir()
    with pytest.raises(ManifestError) as err:
        read_manifest(manifest, folder / "out")
    lines = sorted({line for line, _ in err.value.problems})
    assert lines == list(range(3, 15))
    text = str(err.value)
    for needle in (":3: output '../up.mp4' leaves OUTDIR", ":5: input 'in/missing.tsv': no such file",
                   ":6: output 'ok.mp4' is also written by line 2", ":7: fps: frame rate", ":8: map 'no-such-map'",
                   ":9: method 'warp': unknown; valid: flow", ":10: bank 'nobank':", "bank.yaml",
                   ":12: output 'link/x.mp4' leads outside OUTDIR", ":13: output 'j.mp4.lipsync.json' ends with"):
        assert needle in text, needle
    # the CLI: exit 2, every problem on stderr, nothing written or started
    outdir = folder / "fresh"
    assert main(["batch", str(manifest), "-o", str(outdir), "--quiet"]) == 2
    assert str(manifest) + ":14:" in capsys.readouterr().err
    assert not outdir.exists()


@pytest.mark.parametrize("text, line, needle", [
    ("", 1, "empty manifest"),
    ("input,output,colour\n", 1, "unknown column 'colour'"),
    ("input,bank\n", 1, "lacks the 'output' column"),
    ("input,output\n", 1, "no clips"),
    ("input,output\nin/a.tsv,a.mp4,extra\n", 2, "3 cells but the header has 2"),
    ('{"input": "in/a.tsv", "output": "a.mp4"}\n[1, 2]\n', 2, "expected a JSON object"),
    ('{"input": "in/a.tsv", "output": "a.mp4"}\n{"input": \n', 2, "not a JSON object"),
    ('{"input": "in/a.tsv", "output": "a.mp4", "fps": true}\n', 1, "fps: expected text or a number"),
    ('{"input": "in/a.tsv", "output": "a.mp4", "speed": 2}\n', 1, "unknown field 'speed'"),
    ('{"output": "a.mp4"}\n', 1, "missing 'input'"),
])
def test_malformed_manifests(folder, text, line, needle):
    ext = ".jsonl" if text.startswith("{") else ".csv"
    with pytest.raises(ManifestError) as err:
        read_manifest(write(folder / f"m{ext}", text))
    assert err.value.problems[0][0] == line and needle in err.value.problems[0][1]


def test_clip_key_follows_every_input_and_option(folder, synthetic_bank_dir, monkeypatch):
    import lipsync

    def job(**changes):
        cols = {"input": "in/a.tsv", "output": "a.mp4", "bank": str(synthetic_bank_dir)}
        cols.update(changes)
        m = write(folder / "k.jsonl", json.dumps(cols) + "\n")
        return read_manifest(m)[0]

    base = clip_key(job(), "d" * 64)
    assert base == clip_key(job(), "d" * 64)
    assert base == clip_key(job(output="elsewhere/a.mp4"), "d" * 64)  # where it goes is not what it is
    write(folder / "map.yaml", "name: m\nsilence: X\nfallback: O\nmap: {AA: O}\n")
    different = [clip_key(job(), "e" * 64), clip_key(job(fps=30), "d" * 64), clip_key(job(timing="linear"), "d" * 64),
                 clip_key(job(method="dissolve"), "d" * 64), clip_key(job(map="map.yaml"), "d" * 64),
                 clip_key(job(text="hello"), "d" * 64), clip_key(job(output="a.mkv"), "d" * 64)]
    write(folder / "map.yaml", "name: m\nsilence: X\nfallback: O\nmap: {AA: E}\n")  # same name, new content
    different.append(clip_key(job(map="map.yaml"), "d" * 64))
    (folder / "in" / "a.tsv").write_text("0.00\tX\n0.40\tO\n0.90\tX\n")
    different.append(clip_key(job(), "d" * 64))
    monkeypatch.setattr(lipsync, "__version__", "999")
    different.append(clip_key(job(), "d" * 64))
    assert len({base, *different}) == len(different) + 1


def test_sidecar_vouches_only_for_the_file_it_was_written_with(tmp_path):
    out = tmp_path / "sub" / "a.mp4"
    write_done(out, b"video bytes", "k" * 64, {"frames": 3, "seconds": 0.12})
    assert read_done(out, "k" * 64)["frames"] == 3
    assert read_done(out, "j" * 64) is None                       # other inputs
    out.write_bytes(b"video bytez")                                # same size, changed
    assert read_done(out, "k" * 64) is None
    out.write_bytes(b"video bytes")
    sidecar_path(out).write_text('{"key": "' + "k" * 20)           # cut short
    assert read_done(out, "k" * 64) is None
    sidecar_path(out).unlink()
    assert read_done(out, "k" * 64) is None
    assert sorted(p.name for p in out.parent.iterdir()) == ["a.mp4"]  # no temporary files left


def test_bank_pack_is_content_addressed_and_unpacks_to_the_same_bank(tmp_path, synthetic_bank_dir):
    import shutil

    src = tmp_path / "bank"
    shutil.copytree(synthetic_bank_dir, src, ignore=shutil.ignore_patterns(".lipsync"))
    (src / "notes.txt").write_text("not part of the bank")
    (src / ".lipsync").mkdir()
    (src / ".lipsync" / "junk.npz").write_bytes(b"x" * 100)
    pack = pack_bank(src)
    names = [rel for rel, _ in pack.files]
    assert names[0] == "bank.yaml" and sorted(names[1:]) == sorted(f"{v}.png" for v in synthetic.SHAPES)
    assert pack.nbytes == sum((src / n).stat().st_size for n in names)
    assert pack_bank(synthetic_bank_dir).digest == pack.digest  # same files, other folder
    # a changed byte in one image is another bank
    img = src / "O.png"
    data = bytearray(img.read_bytes())
    data[-20] ^= 1  # inside IEND's CRC: the file differs, the pixels do not
    img.write_bytes(bytes(data))
    try:
        other = pack_bank(src).digest
    except Exception:  # a strict PNG decoder may refuse it; then change the yaml instead
        other = None
    if other is None:
        img.write_bytes(pack.files[names.index("O.png")][1])
        (src / "bank.yaml").write_text((src / "bank.yaml").read_text() + "\n# edited\n")
        other = pack_bank(src).digest
    assert other != pack.digest

    cache = tmp_path / "cache"
    local = local_bank(pack, cache)
    original = Bank.load(synthetic_bank_dir)
    assert local.folder == cache / "banks" / pack.digest
    assert local.bank.names == original.names and local.bank.line_names == original.line_names
    for v in original.names:
        assert np.array_equal(local.bank.images[v], original.images[v])
        assert np.array_equal(local.bank.lines[v], original.lines[v])
    assert local_bank(pack, cache) is local  # loaded once per process

    # a damaged unpacked folder (another process, same cache) is unpacked again
    from lipsync.batch import bankpack

    bankpack._LOADED.clear()
    (local.folder / "X.png").write_bytes(b"broken")
    again = local_bank(pack, cache)
    assert np.array_equal(again.bank.images["X"], original.images["X"])
    assert sorted(p.name for p in (cache / "banks").iterdir()) == [pack.digest]  # no temp folders left


def test_shipped_store_entries_are_installed_once_and_damage_is_a_miss(tmp_path, synthetic_bank_dir):
    from lipsync.batch.worker import pair_task

    pack = pack_bank(synthetic_bank_dir)
    a, b = pack.names[0], pack.names[1]
    key, data = pair_task(pack, a, b, str(tmp_path / "computed"))
    # computed on one "machine", shipped to another: byte-identical entry, same flows
    other = local_bank(pack, tmp_path / "other")
    assert install_entries(other, [(key, data)]) == 1
    assert install_entries(other, [(key, data)]) == 0
    assert other.store.pair_path(key).read_bytes() == data
    got = other.store.get_pair(other.bank, a, b)
    want = local_bank(pack, tmp_path / "computed").store.get_pair(other.bank, a, b)
    assert np.array_equal(got[0].full(), want[0].full()) and np.abs(got[0].full()).max() > 1
    # a second pair task finds the entry on its machine instead of computing it again
    path = local_bank(pack, tmp_path / "computed").store.pair_path(key)
    before = path.stat().st_mtime_ns
    assert pair_task(pack, a, b, str(tmp_path / "computed")) == (key, data)
    assert path.stat().st_mtime_ns == before
    # a damaged shipped entry is a store miss (recomputed), never used
    bad = bytearray(data)
    bad[len(bad) // 2] ^= 0xFF
    third = local_bank(pack, tmp_path / "third")
    install_entries(third, [(key, bytes(bad))])
    with pytest.warns(UserWarning, match="unusable flow store entry"):
        assert third.store.get_pair(third.bank, a, b) is None


def test_scheduler_address_checked_and_unreachable_scheduler_is_an_error(folder, monkeypatch, capsys):
    from lipsync.batch import run

    manifest = write(folder / "m.csv", "input,output\nin/a.tsv,a.mp4\n")
    assert main(["batch", str(manifest), "-o", str(folder / "o"), "--scheduler", "127.0.0.1:8786"]) == 2
    assert "tcp://HOST:PORT" in capsys.readouterr().err
    assert main(["batch", str(manifest), "-o", str(folder / "o"), "--workers", "0"]) == 2
    assert "--workers must be at least 1" in capsys.readouterr().err
    assert not (folder / "o").exists()  # refused before anything was written
    monkeypatch.setattr(run, "CONNECT_TIMEOUT_S", 1)
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert main(["batch", str(manifest), "-o", str(folder / "o"), "--scheduler", f"tcp://127.0.0.1:{port}",
                 "--quiet"]) == 1
    assert f"cannot reach the dask scheduler at tcp://127.0.0.1:{port}" in capsys.readouterr().err
    report = json.loads((folder / "o" / "lipsync-batch-report.json").read_text())
    assert [c["status"] for c in report["clips"]] == ["not run"]
    assert not (folder / "o" / "a.mp4").exists()


def test_work_folders_of_dead_workers_are_removed(tmp_path):
    from lipsync.batch import worker

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp / f"clip-{dead.pid}-abc").mkdir()
    (tmp / f"clip-{dead.pid}-abc" / "out.mp4").write_bytes(b"half")
    (tmp / f"clip-{os.getpid()}-live").mkdir()  # a live process's folder stays
    fresh = worker._work_folder(tmp_path)
    assert fresh.parent == tmp and fresh.name.startswith(f"clip-{os.getpid()}-")
    assert sorted(p.name for p in tmp.iterdir()) == sorted([f"clip-{os.getpid()}-live", fresh.name])
