"""Flow store: reuse, invalidation of only the affected pairs, damaged entries as misses."""

import json
import shutil
import subprocess
import sys

import cv2
import numpy as np
import pytest

from lipsync.banks.bank import Bank
from lipsync.morphing.normalise import normalise
from lipsync.morphing.preprocess import all_pairs, bank_pair_flows, preprocess
from lipsync.morphing.render import Renderer
from lipsync.morphing.store import FlowStore, StoreWarning, _read_flat_entry, apply_deadzone


@pytest.fixture()
def bank_dir(synthetic_bank_dir, tmp_path):
    d = tmp_path / "bank"
    shutil.copytree(synthetic_bank_dir, d)
    return d


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "lipsync", *args], capture_output=True, text=True)


def test_preprocess_twice_then_change_one_image(bank_dir):
    first = run_cli("preprocess", str(bank_dir), "--jobs", "2", "--quiet")
    assert first.returncode == 0, first.stderr
    assert "6 pairs: 6 computed, 0 reused" in first.stdout
    second = run_cli("preprocess", str(bank_dir), "--quiet")
    assert "6 pairs: 0 computed, 6 reused" in second.stdout
    # Change one viseme's image: only the 3 pairs involving it are recomputed.
    img = cv2.imread(str(bank_dir / "O.png"))
    img[0, 0] = 255 - img[0, 0]
    cv2.imwrite(str(bank_dir / "O.png"), img)
    third = run_cli("preprocess", str(bank_dir), "--quiet")
    assert "6 pairs: 3 computed, 3 reused" in third.stdout, third.stdout
    # the old O's three pairs and its normalised-image entry (if any) are stale now
    assert "3 stale entries (--prune removes them)" in third.stdout, third.stdout
    fourth = run_cli("preprocess", str(bank_dir), "--quiet", "--prune")
    assert "0 computed, 6 reused" in fourth.stdout and "3 stale entries removed" in fourth.stdout
    assert len(list((bank_dir / ".lipsync" / "flows").glob("*.flow"))) == 6
    assert "stale" not in run_cli("preprocess", str(bank_dir), "--quiet").stdout


def test_truncated_entry_is_recomputed_with_a_warning(bank_dir):
    bank = Bank.load(bank_dir)
    store = FlowStore.for_bank(bank)
    preprocess(bank, store=store, jobs=1, quiet=True)
    entries = sorted((store.root / "flows").glob("*.flow"))
    assert len(entries) == 6
    victim = entries[2]
    data = victim.read_bytes()
    victim.write_bytes(data[: len(data) // 2])
    result = run_cli("preprocess", str(bank_dir), "--quiet")
    assert result.returncode == 0
    assert "1 computed, 5 reused" in result.stdout
    assert "unusable flow store entry" in result.stderr and victim.name in result.stderr
    assert victim.read_bytes() == data  # recomputed to the same bytes


@pytest.mark.parametrize("damage", ["flip", "garbage", "empty"])
def test_damaged_entries_are_misses_not_crashes(bank_dir, damage):
    bank = Bank.load(bank_dir)
    store = FlowStore(bank_dir / "store")
    preprocess(bank, store=store, jobs=1, quiet=True)
    key = store.pair_key(bank, "X", "O", normalise(bank).axis)
    path = store.pair_path(key)
    data = bytearray(path.read_bytes())
    if damage == "flip":
        data[len(data) // 2] ^= 0x40
    elif damage == "garbage":
        data = bytearray(b"\x00\x01junk" * 10)
    else:
        data = bytearray()
    path.write_bytes(bytes(data))
    with pytest.warns(StoreWarning):
        assert store.get_pair(bank, "X", "O") is None
    report = preprocess(bank, store=store, jobs=1, quiet=True)
    assert report.computed == 1


def test_stored_fields_match_computed_fields(bank_dir):
    bank = Bank.load(bank_dir)
    store = FlowStore(bank_dir / "store")
    preprocess(bank, store=store, jobs=1, quiet=True)
    nb = normalise(bank)
    fwd, bwd, axis = bank_pair_flows(nb, "A", "E")  # the line flows, refined (the default)
    assert axis == nb.axis is not None
    got_f, got_b = store.get_pair(bank, "A", "E")
    # the dead zone, then float16 rounding: the documented cost of compact storage
    for got, want in ((got_f, fwd), (got_b, bwd)):
        shrunk = apply_deadzone(want)
        err = np.abs(got.full() - shrunk)
        assert err.max() <= np.abs(shrunk).max() * 2.0 ** -11 + 1e-6
        assert np.abs(got.full() - want).max() <= 0.25 + 0.01
        # below the dead zone nothing moves; above it the motion is kept
        small = np.hypot(want[..., 0], want[..., 1]) < 0.25
        assert np.all(got.full()[small] == 0) and np.any(got.full() != 0)
    # reversed order gives swapped roles
    rf, rb = store.get_pair(bank, "E", "A")
    np.testing.assert_array_equal(rf.full(), got_b.full())
    # symmetric storage keeps about half the columns of each crop, fields and tables alike
    meta, arrays = _read_flat_entry(store.pair_path(store.pair_key(bank, "A", "E", nb.axis)))
    for name in ("forward", "backward"):
        y0, y1, x0, x1 = meta[name]["crop"]
        assert arrays[name].shape[1] == meta[name]["half"] <= (x1 - x0 + 1) // 2 + 1
        tab = arrays[f"inverse_{name}"]
        assert meta["tables"]["half"] and tab.shape[2] == -(-meta["tables"]["coarse_width"] // 2)
        assert tab.dtype == np.int16 and tab.shape[0] == meta["tables"]["steps"]


def _member_span(path, name):
    """Byte range of one array member inside a flat store entry."""
    data = path.read_bytes()
    hlen = int.from_bytes(data[12:16], "little")
    header = json.loads(data[16:16 + hlen])
    start = -(-(16 + hlen) // 64) * 64 + header["members"][name]["offset"]
    m = header["members"][name]
    n = int(np.prod(m["shape"])) * np.dtype(m["dtype"]).itemsize
    return start, start + n


@pytest.mark.parametrize("member", ["inverse_forward", "inverse_backward", "forward"])
def test_a_damaged_table_or_field_is_a_miss(bank_dir, member):
    bank = Bank.load(bank_dir)
    store = FlowStore(bank_dir / "store")
    preprocess(bank, store=store, jobs=1, quiet=True)
    path = store.pair_path(store.pair_key(bank, "X", "O", normalise(bank).axis))
    good = path.read_bytes()
    lo, hi = _member_span(path, member)
    assert hi - lo > 100
    data = bytearray(good)
    data[(lo + hi) // 2] ^= 0x01  # one bit of one table value
    path.write_bytes(bytes(data))
    with pytest.warns(StoreWarning, match="checksum mismatch"):
        assert store.get_pair(bank, "X", "O") is None
    with pytest.warns(StoreWarning):
        r = Renderer(bank, store=store)
        frame = r.render("X", "O", 0.5).copy()
    assert path.read_bytes() == good  # recomputed to the same bytes by the renderer
    np.testing.assert_array_equal(frame, Renderer(bank, store=store).render("X", "O", 0.5))


def test_entries_of_an_older_format_are_misses(bank_dir, monkeypatch):
    from lipsync.morphing import store as store_mod

    bank = Bank.load(bank_dir)
    store = FlowStore(bank_dir / "store")
    monkeypatch.setattr(store_mod, "FORMAT_VERSION", 3)
    preprocess(bank, store=store, jobs=1, quiet=True)
    monkeypatch.setattr(store_mod, "FORMAT_VERSION", 4)
    # the key carries the version: old entries are simply not found (and reported stale)
    assert store.get_pair(bank, "X", "O") is None
    report = preprocess(bank, store=store, jobs=1, quiet=True)
    assert report.computed == 6 and report.stale >= 6


def test_store_entries_are_deterministic(bank_dir, tmp_path):
    bank = Bank.load(bank_dir)
    s1, s2 = FlowStore(tmp_path / "s1"), FlowStore(tmp_path / "s2")
    preprocess(bank, store=s1, jobs=1, quiet=True)
    preprocess(bank, store=s2, jobs=2, quiet=True)
    names1 = sorted(p.name for p in s1.entries())
    assert names1 == sorted(p.name for p in s2.entries())
    for name in names1:
        assert (s1.root / "flows" / name).read_bytes() == (s2.root / "flows" / name).read_bytes()
    assert len(all_pairs(bank.names)) == 6


def test_stale_temp_files_of_dead_processes_are_removed(bank_dir):
    bank = Bank.load(bank_dir)
    store = FlowStore(bank_dir / "store")
    (store.root / "flows").mkdir(parents=True)
    stale = store.root / "flows" / ".tmp-999999999-abcd"
    stale.write_bytes(b"half")
    preprocess(bank, store=store, jobs=1, quiet=True)
    assert not stale.exists()


def _rewrite_entry(path, edit_body):
    """Change an entry's bytes with ``edit_body(bytearray)`` and recompute its CRC: damage that
    only the values themselves can reveal."""
    import zlib

    data = bytearray(path.read_bytes())
    body = data[12:]
    edit_body(body)
    data[12:] = body
    data[8:12] = zlib.crc32(bytes(body)).to_bytes(4, "little")
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("where", ["field", "header"])
def test_non_finite_values_under_a_valid_crc_are_a_miss(bank_dir, where):
    # issue 19, item 8: NaN in a stored field made --method splat fail with a traceback
    bank = Bank.load(bank_dir)
    store = FlowStore(bank_dir / "store")
    preprocess(bank, store=store, jobs=1, quiet=True)
    path = store.pair_path(store.pair_key(bank, "X", "O", normalise(bank).axis))
    good = path.read_bytes()
    if where == "field":
        lo, hi = _member_span(path, "forward")

        def edit(body):
            body[lo - 12:lo - 12 + 2] = np.array([np.nan], np.float16).tobytes()
    else:
        hlen = int.from_bytes(good[12:16], "little")
        header = good[16:16 + hlen]
        assert b'"deadzone": 0.25' in header

        def edit(body):
            at = 4 + header.index(b'"deadzone": 0.25') + len(b'"deadzone": ')
            body[at:at + 4] = b"NaN "
    _rewrite_entry(path, edit)
    want = Renderer(bank, store=FlowStore(bank_dir / "fresh"), method="splat").render("X", "O", 0.4).copy()
    with pytest.warns(StoreWarning, match="unusable flow store entry") as caught:
        got = Renderer(bank, store=store, method="splat").render("X", "O", 0.4)
    assert any(path.name in str(w.message) for w in caught)
    np.testing.assert_array_equal(got, want)
    assert path.read_bytes() == good  # recomputed and written again


def test_a_folder_where_an_entry_belongs_is_replaced(bank_dir):
    # issue 19, item 8: a miss for render, but preprocess exited 1
    bank = Bank.load(bank_dir)
    store = FlowStore(bank_dir / "store")
    path = store.pair_path(store.pair_key(bank, "X", "O", normalise(bank).axis))
    (path / "junk").mkdir(parents=True)
    result = run_cli("preprocess", str(bank_dir), "--store", str(store.root), "--quiet")
    assert result.returncode == 0, result.stderr
    assert path.is_file() and store.get_pair(bank, "X", "O") is not None


def test_check_does_not_count_damaged_entries(bank_dir):
    bank = Bank.load(bank_dir)
    store = FlowStore(bank_dir / ".lipsync")
    preprocess(bank, store=store, jobs=1, quiet=True)
    result = run_cli("check", str(bank_dir))
    assert "6 of 6 pairs present" in result.stdout
    path = store.pair_path(store.pair_key(bank, "X", "O", normalise(bank).axis))
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x10
    path.write_bytes(bytes(data))
    result = run_cli("check", str(bank_dir))
    assert result.returncode == 0
    assert "5 of 6 pairs present, 1 damaged" in result.stdout, result.stdout
    assert path.name in result.stderr and "checksum" in result.stderr
