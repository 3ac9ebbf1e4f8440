"""Curves in bank.yaml: polylines and cubic Béziers expanded into segments by arc length."""

import math

import numpy as np
import pytest
import yaml

import synthetic
from lipsync.banks.bank import Bank, Feature, mirror_partner_index
from lipsync.errors import BankError
from lipsync.morphing.normalise import bank_axis, is_symmetric, symmetric_lines
from lipsync.encode.preview import draw_lines, feature_lines
from lipsync.morphing.render import Renderer
from lipsync.morphing.store import FlowStore


def write(folder, mutate=None):
    synthetic.write_bank(folder)
    spec = yaml.safe_load((folder / "bank.yaml").read_text())
    if mutate:
        mutate(spec)
    (folder / "bank.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    return folder


def mouth_curves(spec, segments=6):
    """Replace each viseme's upper/lower lines with Béziers along the true ellipse."""
    cx, cy = synthetic.CENTRE
    for name, entry in spec["visemes"].items():
        rx, ry = synthetic.SHAPES[name]
        k = 0.5523  # cubic quarter-ellipse handle length
        lines = entry["lines"]
        for side, sx in (("l", -1), ("r", 1)):
            for lip, sy in (("upper", -1), ("lower", 1)):
                lines.pop(f"{lip}_{side}")
                lines[f"{lip}_{side}"] = {"bezier": [[cx + sx * rx, cy], [cx + sx * rx, cy + sy * k * ry],
                                                     [cx + sx * k * rx, cy + sy * ry], [cx, cy + sy * ry]],
                                          "segments": segments}


def test_straight_bezier_is_the_line():
    p, q = np.array([10.0, 20.0]), np.array([70.0, 50.0])
    thirds = Feature("bezier", np.array([p, p + (q - p) / 3, p + 2 * (q - p) / 3, q]), segments=1)
    np.testing.assert_allclose(thirds.expand(), [[p, q]], atol=1e-12)
    # Control points at the ends make t run as smoothstep along the line; arc length does not
    # care: four equal quarters.
    ends = Feature("bezier", np.array([p, p, q, q]), segments=4)
    want = np.array([p + (q - p) * i / 4 for i in range(5)])
    np.testing.assert_allclose(ends.expand()[:, 0], want[:-1], atol=1e-3)
    np.testing.assert_allclose(ends.expand()[:, 1], want[1:], atol=1e-3)


def test_bezier_bank_with_a_straight_curve_equals_the_line_bank(tmp_path):
    line_bank = Bank.load(write(tmp_path / "lines"))

    def straight(spec):
        for entry in spec["visemes"].values():
            (px, py), (qx, qy) = entry["lines"]["width"]
            entry["lines"]["width"] = {"bezier": [[px, py], [px + (qx - px) / 3, py], [px + 2 * (qx - px) / 3, py],
                                                  [qx, qy]], "segments": 1}
    curve_bank = Bank.load(write(tmp_path / "curves", straight))
    i = line_bank.line_names.index("width")
    assert curve_bank.line_names[i] == "width#0"
    for v in line_bank.names:
        np.testing.assert_allclose(curve_bank.lines[v], line_bank.lines[v], atol=1e-9)
    a = Renderer(line_bank, method="beier-neely").render("X", "O", 0.5).copy()
    b = Renderer(curve_bank, method="beier-neely").render("X", "O", 0.5)
    assert np.abs(a.astype(int) - b).max() <= 1


def parabola_arc(x):
    """Arc length of y = x^2 from 0 to x (closed form)."""
    return x * math.sqrt(1 + 4 * x * x) / 2 + math.asinh(2 * x) / 4


def test_arc_length_correspondence_on_a_parabola():
    # y = x^2 on [0, 1] is the quadratic Bézier (0,0) (0.5,0) (1,1); degree-elevated to a cubic
    # it is exactly (0,0) (1/3,0) (2/3,1/3) (1,1), with x(t) = t. Scaled by 100 px.
    s = 100.0
    f = Feature("bezier", s * np.array([[0, 0], [1 / 3, 0], [2 / 3, 1 / 3], [1, 1]]), segments=5)
    got = np.concatenate([f.expand()[:, 0], f.expand()[-1:, 1]])
    total = parabola_arc(1.0)
    for i, (x, y) in enumerate(got):
        lo, hi = 0.0, 1.0  # bisection for the x whose arc length is i/5 of the total
        for _ in range(60):
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if parabola_arc(mid) < total * i / 5 else (lo, mid)
        assert abs(x - s * lo) < 0.01 and abs(y - s * lo * lo) < 0.01, (i, x, y, s * lo)


def test_polyline_with_segments_resamples_and_without_keeps_vertices():
    pts = np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 10.0]])
    np.testing.assert_allclose(Feature("polyline", pts).expand(), [[[0, 0], [30, 0]], [[30, 0], [30, 10]]])
    chain = Feature("polyline", pts, segments=4).expand()
    np.testing.assert_allclose(chain[:, 0], [[0, 0], [10, 0], [20, 0], [30, 0]], atol=1e-9)
    np.testing.assert_allclose(chain[-1, 1], [30, 10])


def test_mirror_partners_of_curves():
    names = ["lip_l#0", "lip_l#1", "lip_r#0", "lip_r#1", "chin#0", "chin#1", "chin#2", "nose"]
    assert mirror_partner_index(names).tolist() == [2, 3, 0, 1, 6, 5, 4, 7]
    # A chin curve crossing the axis x = 50 symmetrically stays as it is when normalised,
    # and a perturbed one becomes symmetric.
    chin = Feature("bezier", np.array([[20.0, 80], [30, 95], [70, 95], [80, 80]]), segments=3).expand()
    lines = np.concatenate([chin, [[[50.0, 10], [50, 30]]]])
    names = ["chin#0", "chin#1", "chin#2", "nose"]
    np.testing.assert_allclose(symmetric_lines(lines, names, 50.0), lines, atol=1e-9)
    bent = lines.copy()
    bent[0, 0] += [2.0, 1.0]
    fixed = symmetric_lines(bent, names, 50.0)
    assert is_symmetric(fixed, names, 50.0)
    assert np.abs(fixed - lines).max() <= 1.0 + 1e-9  # half the perturbation


def test_curve_bank_loads_normalises_and_renders(tmp_path):
    bank = Bank.load(write(tmp_path / "b", mouth_curves))
    assert bank.feature_names.count("upper_l") == 1
    assert [n for n in bank.line_names if n.startswith("upper_l")] == [f"upper_l#{i}" for i in range(6)]
    assert bank.features["O"]["upper_l"].kind == "bezier"
    assert bank_axis(bank) == 95.5
    r = Renderer(bank, method="flow", store=FlowStore(tmp_path / "store"))
    x, o = bank.images["X"], bank.images["O"]
    mid = r.render("X", "O", 0.5).copy()
    assert np.array_equal(r.render("X", "O", 0.0), x) and np.array_equal(r.render("X", "O", 1.0), o)
    # The true in-between (rx, ry halfway) is closer to the morph than either end image.
    truth = synthetic.draw(26.0, 12.0).astype(float)
    err = np.abs(mid - truth).mean()
    assert err < np.abs(x - truth).mean() and err < np.abs(o - truth).mean()


def test_store_key_changes_with_a_curve(tmp_path):
    bank = Bank.load(write(tmp_path / "a", mouth_curves))

    def moved(spec):
        mouth_curves(spec)
        spec["visemes"]["O"]["lines"]["upper_l"]["bezier"][1][1] -= 3.0  # one handle, 3 px
    other = Bank.load(write(tmp_path / "b", moved))
    store = FlowStore(tmp_path / "store")
    assert store.pair_key(bank, "X", "A", None) == store.pair_key(other, "X", "A", None)
    assert store.pair_key(bank, "X", "O", None) != store.pair_key(other, "X", "O", None)


@pytest.mark.parametrize("mutate, pattern, viseme, feature", [
    (lambda s: (mouth_curves(s), s["visemes"]["O"]["lines"]["upper_l"].update(segments=5)),
     r"viseme 'O', line 'upper_l': 5 segments but 6 in viseme 'X'", "O", "upper_l"),
    (lambda s: (mouth_curves(s), s["visemes"]["A"]["lines"]["lower_r"]["bezier"].append([1, 2])),
     r"viseme 'A', line 'lower_r'.*3k\+1 control points", "A", "lower_r"),
    (lambda s: [e["lines"].update(width={"polyline": [[1, 1], [1, 1] if v == "E" else [3, 1], [5, 5]]})
                for v, e in s["visemes"].items()],
     r"viseme 'E', line 'width': segment 0 has zero length", "E", "width"),
    (lambda s: s["visemes"]["E"]["lines"].update(width={"polyline": [[1, 1], [5, 5]], "segmnets": 2}),
     r"viseme 'E', line 'width'.*unknown key 'segmnets'", "E", "width"),
    (lambda s: s["visemes"]["A"]["lines"].update(width={"polyline": [[1, 1], [5, 5]]}),
     r"viseme 'A', line 'width': a line here but a curve in viseme 'X'|"
     r"viseme 'A', line 'width'.*curve", "A", "width"),
    (lambda s: (mouth_curves(s), s["visemes"]["X"]["lines"]["upper_r"].update(segments=4),
                [e["lines"]["upper_r"].update(segments=4) for e in s["visemes"].values()]),
     r"line 'upper_l': 6 segments but its mirror partner 'upper_r' has 4", "X", "upper_l"),
    (lambda s: s["visemes"]["O"]["lines"].update({"bad#name": [[1, 1], [5, 5]]}),
     r"viseme 'O', line 'bad#name': names use", "O", "bad#name"),
])
def test_curve_errors_name_file_line_viseme_and_feature(tmp_path, mutate, pattern, viseme, feature):
    folder = write(tmp_path / "b", mutate)
    with pytest.raises(BankError, match=pattern) as exc:
        Bank.load(folder)
    assert exc.value.path.endswith("bank.yaml") and exc.value.line is not None
    assert str(exc.value).startswith(f"{folder / 'bank.yaml'}:{exc.value.line}: ")
    text = (folder / "bank.yaml").read_text().splitlines()
    assert feature in text[exc.value.line - 1] or exc.value.line - 1 < len(text)
    assert exc.value.viseme == viseme and exc.value.feature == feature


def test_error_line_points_at_the_feature(tmp_path):
    folder = write(tmp_path / "b", lambda s: (mouth_curves(s), s["visemes"]["O"]["lines"]["upper_l"].update(segments=5)))
    with pytest.raises(BankError) as exc:
        Bank.load(folder)
    lines = (folder / "bank.yaml").read_text().splitlines()
    assert lines[exc.value.line - 1].strip().startswith("upper_l:")
    # and it is the one inside viseme O
    assert [ln.strip() for ln in lines[:exc.value.line] if ln.startswith("  ") and not ln.startswith("   ")][-1] == "O:"


def test_preview_draws_curves_along_the_curve():
    img = np.zeros((100, 100, 3), np.uint8)
    seg = Feature("bezier", np.array([[10.0, 50], [10, 10], [90, 10], [90, 50]]), segments=8).expand()
    out = draw_lines(img, feature_lines(["arch#%d" % i for i in range(8)], seg), labels=False)
    # The curve's top (t = 1/2) is at y = 50 - 0.75 * 40 = 20 on x = 50: drawn there, and not
    # on the straight chord between its ends.
    assert out[19:22, 49:52].any()
    assert not out[48:53, 40:60].any()


def test_huge_and_odd_curve_values_are_bank_errors(tmp_path):
    for i, value in enumerate([{"polyline": [[10 ** 400, 1], [2, 2]]}, {"bezier": [[1, 1]] * 4, "segments": 2},
                               {"polyline": [[1, 1], [2, 2]], "segments": True}, {"bezier": "abc"},
                               {"polyline": [[1, 1], [2, "x"]]}, {"polyline": [[float("inf"), 1], [2, 2]]}]):
        folder = tmp_path / "b"
        if i == 0:
            synthetic.write_bank(folder)
            original = yaml.safe_load((folder / "bank.yaml").read_text())
        spec = yaml.safe_load(yaml.safe_dump(original))
        for entry in spec["visemes"].values():
            entry["lines"]["width"] = value
        (folder / "bank.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
        with pytest.raises(BankError, match=r"line 'width'"):
            Bank.load(folder)


from hypothesis import given, settings, strategies as st  # noqa: E402

from hypothesis_profiles import FUZZ  # noqa: E402

_num = st.one_of(st.integers(-10 ** 6, 10 ** 6), st.floats(allow_nan=True, allow_infinity=True),
                 st.integers(), st.booleans(), st.text(max_size=3), st.none())
_point = st.one_of(st.lists(_num, min_size=0, max_size=3), _num)
_feature = st.one_of(
    st.lists(_point, max_size=5),
    st.fixed_dictionaries({}, optional={"polyline": st.lists(_point, max_size=8), "bezier": st.lists(_point, max_size=11),
                                        "segments": _num, "other": _num}),
    _num)


@pytest.fixture(scope="module")
def fuzz_bank(tmp_path_factory):
    folder = synthetic.write_bank(tmp_path_factory.mktemp("fuzz") / "b")
    return folder, yaml.safe_load((folder / "bank.yaml").read_text()), Bank.load(folder)


# A third of the quick profile's cases: each loads a whole bank (~0.1 s on a busy machine).
@settings(FUZZ, max_examples=40 if FUZZ.max_examples < 1000 else FUZZ.max_examples)
@given(values=st.lists(_feature, min_size=1, max_size=4), targets=st.lists(st.sampled_from("XAOE"), min_size=1))
def test_fuzzed_features_load_or_raise_bank_error(fuzz_bank, values, targets):
    from lipsync.banks.yamlio import dump_bank

    folder, spec, bank = fuzz_bank
    spec = yaml.safe_load(yaml.safe_dump(spec))
    for v, value in zip(targets, values):
        spec["visemes"][v]["lines"]["width"] = value
    try:
        text = dump_bank(spec)
    except ValueError:  # NaN/inf cannot be written by the editor's writer; write them with PyYAML
        text = yaml.safe_dump(spec, sort_keys=False)
    images = {f"{v}.png": bank.images[v] for v in bank.names}
    try:
        loaded = Bank.from_text(text, folder, images=images)
    except BankError:
        return
    # loaded: every viseme's expanded lines are finite and of one count
    counts = {loaded.lines[v].shape for v in loaded.names}
    assert len(counts) == 1 and all(np.isfinite(loaded.lines[v]).all() for v in loaded.names)
