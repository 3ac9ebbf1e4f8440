"""Crash safety of the flow store, through the real ``lipsync preprocess`` command.

* SIGKILL of the whole process group (the command and its worker processes) at random
  moments, then a rerun: the finished store is byte-identical to an uninterrupted run's
  (same entry names, same bytes, nothing else: no temp files), and right after each kill
  every entry present is already whole.
* Two ``lipsync preprocess`` processes on one bank and one store at once: both succeed and
  the store is identical to a clean run's.
* Damaged entries (a bit flipped in the zip headers, in the payload or in the central
  directory, cut short, another entry's file, a self-consistent zip with altered data that
  only the stored checksum can catch): detected, recomputed with a warning naming the file,
  and the store ends identical to a clean run's. (tests/test_store.py covers the API-level
  cases: a halved entry, garbage, an empty file, a stale temp file.)

The bank is the synthetic subject with the nine Rhubarb shapes (36 pairs, 160x192): big
enough that a run has many separate writes to interrupt, small enough to run in ~2 s.
"""

from __future__ import annotations

import io
import os
import random
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path
from typing import Dict, List

import pytest
import yaml

import synthetic

#: Seed for the kill moments: random, but the same on every run so CI is repeatable.
KILL_SEED = 20240611
#: Kills at a random fraction of the measured clean run time, and kills once a random number
#: of entries has appeared (which guarantees some kills land mid-run on any machine speed).
N_TIMED_KILLS = 2
N_COUNTED_KILLS = 1
#: How often the store is polled while waiting to kill after k entries.
POLL_S = 0.005
#: Upper bound for one preprocess run; only a hang reaches it.
RUN_TIMEOUT_S = 300


def preprocess_cmd(bank: Path, store: Path) -> List[str]:
    return [sys.executable, "-m", "lipsync", "preprocess", str(bank), "--jobs", "2", "--quiet",
            "--store", str(store)]


def run_to_completion(bank: Path, store: Path) -> subprocess.CompletedProcess:
    result = subprocess.run(preprocess_cmd(bank, store), capture_output=True, text=True, timeout=RUN_TIMEOUT_S)
    assert result.returncode == 0, result.stderr
    return result


def snapshot(store: Path) -> Dict[str, bytes]:
    """Every file under the store (hidden ones included), by relative path."""
    if not store.exists():
        return {}
    return {p.relative_to(store).as_posix(): p.read_bytes() for p in sorted(store.rglob("*")) if p.is_file()}


def entry_names(snap: Dict[str, bytes]) -> List[str]:
    return [n for n in snap if n.endswith((".npz", ".flow"))]


@pytest.fixture(scope="module")
def bank(tmp_path_factory) -> Path:
    folder = synthetic.write_bank(tmp_path_factory.mktemp("crash") / "bank", synthetic.RHUBARB_SHAPES)
    # Nudge one line per viseme off mirror symmetry, so that normalisation warps every image
    # and the store also holds the 9 normalised images (entries of the second kind).
    spec = yaml.safe_load((folder / "bank.yaml").read_text())
    for v in spec["visemes"].values():
        v["lines"]["upper_l"][1][0] += 1.5
    (folder / "bank.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    return folder


@pytest.fixture(scope="module")
def reference(bank, tmp_path_factory):
    """An uninterrupted run's store and its wall time."""
    store = tmp_path_factory.mktemp("reference") / "store"
    t0 = time.perf_counter()
    result = run_to_completion(bank, store)
    seconds = time.perf_counter() - t0
    assert "36 pairs: 36 computed, 0 reused" in result.stdout
    snap = snapshot(store)
    names = entry_names(snap)
    # 36 pair entries and 9 normalised images, and nothing else.
    assert sorted(n.split("/")[0] for n in names) == ["flows"] * 36 + ["images"] * 9
    assert len(snap) == len(names)
    return snap, seconds


def start(bank: Path, store: Path) -> subprocess.Popen:
    # Its own session, so one killpg reaches the command and every worker it spawned.
    return subprocess.Popen(preprocess_cmd(bank, store), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)


def kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=RUN_TIMEOUT_S)
    # Workers are reparented when the parent dies; wait until none of the group is left.
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.01)
    raise AssertionError("processes of the killed group are still alive")


def kill_moments(seconds: float):
    rng = random.Random(KILL_SEED)
    moments = [("after seconds", round(rng.uniform(0.2, 1.0) * seconds, 3)) for _ in range(N_TIMED_KILLS)]
    moments += [("after entries", rng.randint(1, 18)) for _ in range(N_COUNTED_KILLS)]
    return moments


def test_sigkill_at_random_moments_then_rerun_gives_the_clean_store(bank, reference, tmp_path):
    ref, seconds = reference
    partial_counts = []
    for i, (how, when) in enumerate(kill_moments(seconds)):
        store = tmp_path / f"store{i}"
        proc = start(bank, store)
        if how == "after seconds":
            time.sleep(when)
        else:
            deadline = time.monotonic() + RUN_TIMEOUT_S
            while len(list((store / "flows").glob("*.flow"))) < when and proc.poll() is None:
                assert time.monotonic() < deadline
                time.sleep(POLL_S)
        kill_group(proc)
        after_kill = snapshot(store)
        # Atomic writes: whatever entry exists right after the kill is whole and correct.
        for name in entry_names(after_kill):
            assert after_kill[name] == ref[name], f"{how} {when}: {name} is not a whole entry"
        n = len(entry_names(after_kill))
        partial_counts.append(n)
        if how == "after entries":
            assert when <= n < len(entry_names(ref)), f"the kill after {when} entries did not land mid-run"
        result = run_to_completion(bank, store)
        kept = sum(name.startswith("flows/") for name in entry_names(after_kill))
        assert f"36 pairs: {36 - kept} computed, {kept} reused" in result.stdout  # whole entries are reused
        final = snapshot(store)
        assert sorted(final) == sorted(ref), f"{how} {when}: different files (temp files left?)"
        for name in ref:
            assert final[name] == ref[name], f"{how} {when}: {name} differs from the clean run's"
    assert any(0 < n < len(entry_names(ref)) for n in partial_counts)


def test_killed_twice_in_a_row_then_rerun(bank, reference, tmp_path):
    ref, _ = reference
    store = tmp_path / "store"
    for k in (4, 12):  # the second run resumes from the first one's entries and is killed too
        proc = start(bank, store)
        while len(list((store / "flows").glob("*.flow"))) < k and proc.poll() is None:
            time.sleep(POLL_S)
        kill_group(proc)
    run_to_completion(bank, store)
    assert snapshot(store) == ref


def test_two_concurrent_runs_on_one_store(bank, reference, tmp_path):
    ref, _ = reference
    store = tmp_path / "store"
    procs = [subprocess.Popen(preprocess_cmd(bank, store), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for _ in range(2)]
    outputs = [p.communicate(timeout=RUN_TIMEOUT_S) for p in procs]
    for p, (out, err) in zip(procs, outputs):
        assert p.returncode == 0, err
        assert "36 pairs:" in out
    assert snapshot(store) == ref
    # And the store is complete: a third run computes nothing.
    assert "0 computed, 36 reused" in run_to_completion(bank, store).stdout


# --------------------------------------------------------------------------- damaged entries

def _flip(data: bytes, pos: int) -> bytes:
    return data[:pos] + bytes([data[pos] ^ 0x01]) + data[pos + 1:]


def _rezip_with_altered_payload(data: bytes) -> bytes:
    """The same entry with one payload byte changed and every zip CRC and size recomputed,
    so only the sha256 stored in the entry's meta can tell."""
    src = zipfile.ZipFile(io.BytesIO(data))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_STORED) as dst:
        for info in src.infolist():
            member = src.read(info)
            if info.filename != "meta.npy":
                member = member[:-1] + bytes([member[-1] ^ 0x01])
            dst.writestr(info, member)
    assert zipfile.ZipFile(io.BytesIO(out.getvalue())).testzip() is None  # the CRCs are right
    return out.getvalue()


DAMAGE = {
    # Offset 10 of a zip is the first member's modification time: neither the CRC nor the
    # arrays' checksum covers it.
    "flip-local-header-time": lambda d, other: _flip(d, 10),
    "flip-local-header-crc": lambda d, other: _flip(d, 14),
    "flip-payload": lambda d, other: _flip(d, len(d) // 2),
    "flip-central-directory": lambda d, other: _flip(d, len(d) - 30),
    "cut-last-byte": lambda d, other: d[:-1],
    "cut-half": lambda d, other: d[: len(d) // 2],
    "empty": lambda d, other: b"",
    "another-entry": lambda d, other: other,
    "consistent-zip-altered-data": lambda d, other: _rezip_with_altered_payload(d),
}


def _flat_header_len(d: bytes) -> int:
    return int.from_bytes(d[12:16], "little")


# Flow entries are flat files (magic, CRC-32, header length, JSON header, arrays).
FLAT_DAMAGE = {
    "flip-magic": lambda d, other: _flip(d, 0),
    "flip-crc": lambda d, other: _flip(d, 9),
    "flip-header-length": lambda d, other: _flip(d, 12),
    "flip-json-header": lambda d, other: _flip(d, 16 + _flat_header_len(d) // 2),
    "flip-payload": lambda d, other: _flip(d, len(d) // 2),
    "flip-last-table-byte": lambda d, other: _flip(d, len(d) - 1),
    "cut-last-byte": lambda d, other: d[:-1],
    "cut-half": lambda d, other: d[: len(d) // 2],
    "append-byte": lambda d, other: d + b"\0",
    "empty": lambda d, other: b"",
    "another-entry": lambda d, other: other,
}


def test_damaged_entries_are_detected_and_recomputed(bank, reference, tmp_path):
    """Every kind of damage at once, each to its own flow entry and its own image entry; one
    run must find all of them, say so for each, recompute them and end with the clean store."""
    ref, _ = reference
    store = tmp_path / "store"
    for name, data in ref.items():
        (store / name).parent.mkdir(parents=True, exist_ok=True)
        (store / name).write_bytes(data)
    victims = {}
    for kind, table in (("flows", FLAT_DAMAGE), ("images", DAMAGE)):
        names = [n for n in entry_names(ref) if n.startswith(kind + "/")]
        assert len(names) >= len(table)
        for i, damage in enumerate(sorted(table)):
            victim, other = names[i], names[(i + 1) % len(names)]
            (store / victim).write_bytes(table[damage](ref[victim], ref[other]))
            assert (store / victim).read_bytes() != ref[victim]
            victims[victim] = damage
    result = run_to_completion(bank, store)
    warned = [line for line in result.stderr.splitlines() if "unusable flow store entry" in line]
    for victim, damage in victims.items():
        assert any(Path(victim).name in line for line in warned), f"{damage} on {victim} went unnoticed"
    assert len(warned) == len(victims)
    n = len(FLAT_DAMAGE)
    assert f"36 pairs: {n} computed, {36 - n} reused" in result.stdout, result.stdout
    assert snapshot(store) == ref
