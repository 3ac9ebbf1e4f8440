"""Bounded reading of JSON and timelines (issue 32, item 9).

* nesting: any depth of ``[``/``{`` (closed or not, with brackets and escaped quotes inside
  strings) through every JSON reader -- timelines by format and by sniffing, the atlas,
  batch manifests -- gives a value or an InputError naming the file, never RecursionError;
  :func:`lipsync._files.json_depth` agrees with a recursive count on real JSON values;
* sizes: a file over :data:`lipsync._files.MAX_INPUT_BYTES` (a sparse file, ``/dev/zero``)
  is refused after reading no more than the limit, with exit 2 from the CLI.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lipsync._files
from hypothesis_profiles import FUZZ, PROFILE
from lipsync._files import MAX_INPUT_BYTES, MAX_JSON_DEPTH, json_depth, load_json
from lipsync.atlas.schema import load_atlas
from lipsync.batch.manifest import read_manifest
from lipsync.errors import InputError
from lipsync.readers import read_timeline

EXAMPLES = 60 if PROFILE == "quick" else 5000

_json = st.recursive(
    st.none() | st.booleans() | st.integers(-10 ** 6, 10 ** 6) | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(alphabet='[]{}"\\ab\n', max_size=12),
    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(alphabet='[]{}"ab', max_size=4), kids,
                                                              max_size=4),
    max_leaves=40)


def _depth(v) -> int:
    if isinstance(v, list):
        return 1 + max((_depth(x) for x in v), default=0)
    if isinstance(v, dict):
        return 1 + max((_depth(x) for x in v.values()), default=0)
    return 0


@settings(FUZZ, max_examples=EXAMPLES)
@given(value=_json)
def test_json_depth_agrees_with_a_recursive_count(value):
    text = json.dumps(value)
    assert json_depth(text) == _depth(value)
    saved = lipsync._files._DEPTH_CHUNK
    lipsync._files._DEPTH_CHUNK = 3  # what carries from chunk to chunk: open strings, backslash runs
    try:
        assert json_depth(text) == _depth(value)
    finally:
        lipsync._files._DEPTH_CHUNK = saved
    if _depth(value) <= MAX_JSON_DEPTH:
        assert load_json(text, "v.json") == json.loads(text)


@st.composite
def _deep(draw):
    """Deep or wide JSON-ish text: brackets, objects, strings holding brackets, unclosed ends."""
    depth = draw(st.integers(1, 50_000))
    opener = draw(st.sampled_from(['[', '{"a":', '[{"b":', '["]]]",']))
    closer = {'[': ']', '{"a":': '}', '[{"b":': '}]', '["]]]",': ']'}[opener]
    body = draw(st.sampled_from(['1', '"x"', '"[[[\\"{{"', '[]', '']))
    closed = draw(st.booleans())
    return opener * depth + body + (closer * depth if closed else ""), depth


def _entry_points(tmp_path: Path, text: str):
    """Every reader of user JSON, each with the file it was given."""
    for name, call in (("t.json", lambda p: read_timeline(p)), ("t.rhubarb.json", lambda p: read_timeline(p, "rhubarb-json")),
                       ("t.gentle", lambda p: read_timeline(p, "gentle")), ("a.json", load_atlas),
                       ("m.jsonl", read_manifest)):
        path = tmp_path / name
        path.write_text(text)
        yield path, call


@settings(FUZZ, max_examples=EXAMPLES // 3)
@given(case=_deep())
def test_deep_json_is_an_input_error_naming_the_file_never_a_recursion_error(tmp_path_factory, case):
    text, depth = case
    tmp_path = tmp_path_factory.mktemp("deep")
    for path, call in _entry_points(tmp_path, text):
        try:
            call(path)
        except InputError as exc:  # refused by depth or by shape: either way naming the file
            assert str(path) in str(exc)
        else:
            assert depth <= MAX_JSON_DEPTH  # nothing this deep is read as a value
        # anything else (RecursionError, KeyError, TypeError ...) fails the test


def test_the_deep_atlas_of_the_report(tmp_path):
    deep = tmp_path / "atlas.json"
    deep.write_text("[" * 100_000)
    with pytest.raises(InputError, match=r"atlas.json:1: JSON nested 100000 levels deep"):
        load_atlas(deep)


def test_a_file_over_the_limit_is_refused_without_reading_it_all(tmp_path):
    big = tmp_path / "huge.tsv"
    with open(big, "wb") as f:  # sparse: 4 GB on paper, nothing on disk
        f.truncate(4 << 30)
    with pytest.raises(InputError, match=f"huge.tsv: larger than {MAX_INPUT_BYTES >> 20} MB: not a timeline file"):
        read_timeline(big)


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="no /dev/zero")
def test_timeline_of_dev_zero_is_exit_2():
    proc = subprocess.run([sys.executable, "-m", "lipsync", "timeline", "/dev/zero"], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 2 and "/dev/zero: larger than 64 MB: not a timeline file" in proc.stderr
    assert "Traceback" not in proc.stderr
