"""``lipsync batch`` on a real dask.distributed LocalCluster (2 worker processes on 127.0.0.1).

Six clips, one broken: every good output must equal ``lipsync render`` of the same clip
frame for frame (both mp4s decoded to raw RGB by the bundled ffmpeg), the broken one must be
in the report with its error, and reruns must skip what is current. One cluster serves the
module; its workers and ports must be gone afterwards.
"""

import json
import os
import socket
import subprocess
import sys
import uuid
import wave

import numpy as np
import psutil
import pytest

import synthetic
from lipsync.cli import main

FPS = 25
CUES_A = [(0.00, "X"), (0.30, "D"), (0.62, "B"), (0.70, "F"), (1.00, "A"), (1.30, "X")]
CUES_B = [(0.00, "X"), (0.10, "C"), (0.50, "E"), (0.90, "H"), (1.20, "X")]
# TIMIT: sample offsets at 16 kHz and ARPAbet phones (mapped by the default map)
PHN = [(0, 1600, "h#"), (1600, 3200, "m"), (3200, 8000, "aa"), (8000, 9600, "p"), (9600, 14400, "iy"),
       (14400, 17600, "h#")]


def write_tsv(path, cues, end):
    path.write_text("".join(f"{t:.2f}\t{v}\n" for t, v in cues) + f"{end:.2f}\tX\n")
    return path


def write_wav(path, seconds, rate=16000):
    t = np.arange(int(seconds * rate)) / rate
    with wave.open(str(path), "wb") as wf:
        wf.setnchannels(1)
        wf.setsampwidth(2)
        wf.setframerate(rate)
        wf.writeframes((0.3 * np.sin(2 * np.pi * 220 * t) * 32767).astype("<i2").tobytes())
    return path


def decode(path):
    import imageio_ffmpeg

    gen = imageio_ffmpeg.read_frames(str(path))
    meta = next(gen)
    w, h = meta["size"]
    return np.stack([np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in gen])


def _refused(address):
    host, port = address.rsplit("/", 1)[-1].split(":")
    with socket.socket() as s:
        s.settimeout(2)
        return s.connect_ex((host, int(port))) != 0


@pytest.fixture(scope="module")
def cluster():
    """One LocalCluster for the module; afterwards no worker process or port may be left."""
    from lipsync.batch import connect

    with connect(workers=2) as (client, _):  # the LocalCluster `lipsync batch` starts by default
        pids = list(client.run(os.getpid).values())
        assert len(pids) == 2
        # workers run without dask's MALLOC_TRIM_THRESHOLD_ (it costs a clip a third more CPU)
        assert set(client.run(os.environ.get, "MALLOC_TRIM_THRESHOLD_").values()) == {None}
        address = client.scheduler.address
        assert address.startswith("tcp://127.0.0.1:")
        # every port the workers, their nannies' host process (a child of this one, started
        # as `python -m lipsync.batch.nannies`: no spawn re-import of the caller's script) and
        # the scheduler (this process) listen on is on 127.0.0.1
        hosts = [c for c in psutil.Process().children() if "lipsync.batch.nannies" in " ".join(c.cmdline())]
        assert len(hosts) == 1 and {psutil.Process(pid).ppid() for pid in pids} == {hosts[0].pid}
        for p in [psutil.Process(pid) for pid in pids] + hosts + [psutil.Process()]:
            listening = [c.laddr for c in p.net_connections("inet") if c.status == psutil.CONN_LISTEN]
            assert listening and all(a.ip == "127.0.0.1" for a in listening), (p, listening)
        yield address, client, pids
    gone = psutil.wait_procs([psutil.Process(p) for p in pids + [hosts[0].pid] if psutil.pid_exists(p)],
                             timeout=10)[1]
    assert not gone, f"worker processes left behind: {gone}"
    assert _refused(address)


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    """A manifest of six clips (one broken) beside its inputs, and the bank."""
    root = tmp_path_factory.mktemp("batch")
    bank = synthetic.write_bank(root / "bank", synthetic.RHUBARB_SHAPES)
    clips = root / "clips"
    clips.mkdir()
    write_tsv(clips / "a.tsv", CUES_A, 1.6)
    write_tsv(clips / "b.tsv", CUES_B, 1.4)
    (clips / "c.phn").write_text("".join(f"{s} {e} {p}\n" for s, e, p in PHN))
    write_wav(clips / "speech.wav", 1.8)
    # a map file of our own: every vowel wide open, so this clip differs from c.mp4
    (clips / "wide.yaml").write_text("name: wide\nsilence: X\nfallback: D\nmap: {M: A, P: A, AA: D, IY: D}\n")
    (clips / "broken.tsv").write_text("0.00\tX\nthis is not a cue\n")
    rows = [  # (input, output, extra columns)
        ("clips/a.tsv", "a.mp4", {}),
        ("clips/b.tsv", "sub/b30.mp4", {"fps": "30", "timing": "linear"}),
        ("clips/c.phn", "c.mp4", {"audio": "clips/speech.wav"}),
        ("clips/broken.tsv", "broken.mp4", {}),
        ("clips/a.tsv", "a-dissolve.mp4", {"method": "dissolve", "fps": "12"}),
        ("clips/c.phn", "c-map.mp4", {"map": "clips/wide.yaml", "fps": "20"}),
    ]
    cols = ["input", "output", "bank", "audio", "fps", "map", "timing", "method"]
    lines = [",".join(cols)]
    for inp, out, extra in rows:
        vals = dict(extra, input=inp, output=out, bank="bank")
        lines.append(",".join(vals.get(c, "") for c in cols))
    (root / "clips.csv").write_text("\n".join(lines) + "\n")
    return root, bank, rows


def _transitions(client, prefix):
    """Keys with ``prefix`` that the scheduler saw go from processing to memory, with their counts."""
    def count(dask_scheduler, prefix=prefix):
        out = {}
        for t in dask_scheduler.transition_log:
            key = t[0]
            if isinstance(key, str) and key.startswith(prefix) and t[1] == "processing" and t[2] == "memory":
                out[key] = out.get(key, 0) + 1
        return out

    return client.run_on_scheduler(count)


def _batch(root, out, address, *extra):
    return main(["batch", str(root / "clips.csv"), "-o", str(out), "--scheduler", address,
                 "--cache", str(root / "cache"), "--quiet", *extra])


@pytest.mark.slow
def test_batch_equals_render_frame_for_frame_and_resumes(cluster, project, tmp_path):
    address, client, worker_pids = cluster
    root, bank, rows = project
    out = root / "out"

    assert _batch(root, out, address) == 1  # one clip failed
    report = json.loads((out / "lipsync-batch-report.json").read_text())
    by_out = {c["output"]: c for c in report["clips"]}
    assert [c["line"] for c in report["clips"]] == [2, 3, 4, 5, 6, 7]
    assert report["summary"]["done"] == 5 and report["summary"]["failed"] == 1

    broken = by_out["broken.mp4"]
    assert broken["status"] == "failed"
    assert str(root / "clips" / "broken.tsv") + ":2:" in broken["error"]  # the user's file and line
    assert "TimelineError" in broken["error"]
    assert not (out / "broken.mp4").exists() and not (out / "broken.mp4.lipsync.json").exists()

    # the clips ran in the cluster's worker processes (which of the two is dask's choice: it
    # places a clip where more of its flows already are), and every flow pair ran once on
    # the cluster for the five clips
    assert {c["worker"].rsplit(":", 1)[1] for c in report["clips"]} <= {str(p) for p in worker_pids}
    pairs = _transitions(client, "lipsync-pair-")
    n_vis = len(synthetic.RHUBARB_SHAPES)
    assert len(pairs) == n_vis * (n_vis - 1) // 2 and set(pairs.values()) == {1}
    assert len(list((root / "cache" / "store" / "flows").glob("*.flow"))) == len(pairs)

    # each good output equals `lipsync render` of the same clip, frame for frame
    total = 0.0
    for inp, name, extra in rows:
        if name == "broken.mp4":
            continue
        ref = tmp_path / name.replace("/", "_")
        args = ["render", str(root / inp), "-o", str(ref), "--bank", str(bank), "--quiet", "--jobs", "1"]
        for opt in ("fps", "map", "timing", "method"):
            if opt in extra:
                args += [f"--{opt}", str(root / extra[opt]) if opt == "map" else extra[opt]]
        if "audio" in extra:
            args += ["--audio", str(root / extra["audio"])]
        assert main(args) == 0
        got, want = decode(out / name), decode(ref)
        assert got.shape == want.shape and got.shape[0] > 10, name
        assert np.array_equal(got, want), f"{name}: batch output differs from lipsync render"
        fps = float(extra.get("fps", FPS))
        assert by_out[name]["frames"] == got.shape[0]
        assert by_out[name]["seconds"] == pytest.approx(got.shape[0] / fps, abs=1e-3)
        side = json.loads((out / (name + ".lipsync.json")).read_text())
        assert side["frames"] == got.shape[0] and len(side["key"]) == 64
        total += got.shape[0] / fps
    assert report["summary"]["video_seconds"] == pytest.approx(total, abs=0.01)
    # frames differ between clips (the comparison is not between blank videos)
    assert not np.array_equal(decode(out / "a.mp4")[20], decode(out / "a.mp4")[0])

    # rerun: the five current clips are skipped (not rewritten), the broken one is tried again
    stamps = {n: os.stat(out / n).st_mtime_ns for _, n, _ in rows if n != "broken.mp4"}
    assert _batch(root, out, address) == 1
    report = json.loads((out / "lipsync-batch-report.json").read_text())
    assert report["summary"]["skipped"] == 5 and report["summary"]["failed"] == 1
    assert stamps == {n: os.stat(out / n).st_mtime_ns for n in stamps}

    # fixed input: only that clip is rendered; then a rerun skips everything without a cluster
    write_tsv(root / "clips" / "broken.tsv", CUES_B, 1.4)
    assert _batch(root, out, address, "--report", str(tmp_path / "r.csv")) == 0
    csv_rows = (tmp_path / "r.csv").read_text().splitlines()
    assert csv_rows[0].startswith("line,input,output,status,error")
    statuses = [r.split(",")[3] for r in csv_rows[1:]]
    assert statuses == ["skipped", "skipped", "skipped", "done", "skipped", "skipped"]
    assert decode(out / "broken.mp4").shape[0] == 35  # 1.4 s at 25 fps
    assert _batch(root, out, "tcp://127.0.0.1:9") == 0  # nothing to do: no scheduler is contacted
    report = json.loads((out / "lipsync-batch-report.json").read_text())
    assert report["summary"]["skipped"] == 6 and report["summary"]["cluster"] == ""

    # an output changed behind our back is rendered again
    data = bytearray((out / "a.mp4").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (out / "a.mp4").write_bytes(bytes(data))
    assert _batch(root, out, address) == 0
    report = json.loads((out / "lipsync-batch-report.json").read_text())
    assert [c["status"] for c in report["clips"]].count("done") == 1
    assert np.array_equal(decode(out / "a.mp4"), decode(tmp_path / "a.mp4"))


@pytest.mark.slow
def test_default_cluster_ctrl_c_stops_cleanly_leaving_whole_outputs_no_processes_or_ports(tmp_path):
    """``lipsync batch`` on its own LocalCluster, then Ctrl-C (SIGINT to the whole process
    group, as a terminal sends it) mid-batch."""
    import signal
    import time

    bank = synthetic.write_bank(tmp_path / "bank", synthetic.RHUBARB_SHAPES)
    rows = []
    for i in range(12):
        write_tsv(tmp_path / f"c{i}.tsv", CUES_A, 1.6 + 0.1 * i)
        rows.append(json.dumps({"input": f"c{i}.tsv", "output": f"c{i}.mp4", "bank": str(bank)}))
    (tmp_path / "m.jsonl").write_text("\n".join(rows) + "\n")
    out = tmp_path / "out"
    tag = uuid.uuid4().hex
    p = subprocess.Popen([sys.executable, "-m", "lipsync", "batch", str(tmp_path / "m.jsonl"), "-o", str(out),
                          "--workers", "2", "--cache", str(tmp_path / "cache")],
                         env=dict(os.environ, LIPSYNC_TEST_TAG=tag), stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not list(out.glob("*.lipsync.json")) and time.monotonic() < deadline and p.poll() is None:
            time.sleep(0.02)
        os.killpg(p.pid, signal.SIGINT)
        err = p.communicate(timeout=120)[1]
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err
    address = err.split(" clips to render on LocalCluster ")[1].split()[0]
    assert address.startswith("tcp://127.0.0.1:") and _refused(address)
    report = json.loads((out / "lipsync-batch-report.json").read_text())
    status = {c["output"]: c["status"] for c in report["clips"]}
    done = sorted(n for n, s in status.items() if s == "done")
    assert done and "not run" in status.values()
    # only whole videos, each with its sidecar; no temporary files
    assert sorted(x.name for x in out.glob("*.mp4")) == done
    for name in done:
        side = json.loads((out / (name + ".lipsync.json")).read_text())
        assert decode(out / name).shape[0] == side["frames"] > 0
    assert not [x for x in out.iterdir() if x.name.startswith(".tmp")]
    left = []
    for q in psutil.process_iter():
        try:
            if q.environ().get("LIPSYNC_TEST_TAG") == tag:
                left.append(q)
        except (psutil.AccessDenied, psutil.NoSuchProcess, psutil.ZombieProcess):
            pass
    assert not left, f"processes left behind: {left}"


def test_worker_with_another_version_fails_its_clips_clearly(cluster, tmp_path, monkeypatch):
    import lipsync

    address = cluster[0]
    bank = synthetic.write_bank(tmp_path / "bank", synthetic.RHUBARB_SHAPES)
    write_tsv(tmp_path / "a.tsv", CUES_B, 1.4)
    (tmp_path / "m.csv").write_text(f"input,output,bank\na.tsv,a.mp4,{bank}\n")
    monkeypatch.setattr(lipsync, "__version__", "0.0.0-client")  # this client, not the workers
    assert main(["batch", str(tmp_path / "m.csv"), "-o", str(tmp_path / "out"), "--scheduler", address,
                 "--cache", str(tmp_path / "cache"), "--quiet"]) == 1
    report = json.loads((tmp_path / "out" / "lipsync-batch-report.json").read_text())
    [clip] = report["clips"]
    assert clip["status"] == "failed" and "this client 0.0.0-client" in clip["error"]
    assert not (tmp_path / "out" / "a.mp4").exists()
