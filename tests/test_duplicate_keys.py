"""A key given twice in bank.yaml or a phoneme map is an error naming the file, the key and both lines (issue 19, item 7).

PyYAML keeps the last of two equal keys silently: a viseme or control line named twice lost
one of them, and ``lipsync check`` said OK. Everything else must load exactly as
``yaml.safe_load`` loads it (checked over random documents).
"""

from __future__ import annotations

import re
import shutil

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from lipsync import _yaml
from lipsync.banks.bank import Bank
from lipsync.cli import main
from lipsync.errors import BankError, MapError
from lipsync.phonetics.phonemes import load_map


@pytest.fixture()
def bank_dir(synthetic_bank_dir, tmp_path):
    d = tmp_path / "bank"
    shutil.copytree(synthetic_bank_dir, d)
    return d


def duplicate_line(text: str, pattern: str) -> tuple:
    """Insert a copy of the first line matching ``pattern`` right after it; returns (text, first, second)."""
    lines = text.splitlines(keepends=True)
    i = next(k for k, line in enumerate(lines) if re.search(pattern, line))
    lines.insert(i + 1, lines[i])
    return "".join(lines), i + 1, i + 2


@pytest.mark.parametrize("pattern, key", [
    (r"^  X:", "X"),                   # a viseme named twice (an empty one, then the real one)
    (r"^      \w+_l:", None),          # a control line named twice (its name is read below)
    (r"^rest:", "rest"),              # a top-level key
])
def test_bank_yaml_with_a_repeated_key_is_refused(bank_dir, capsys, pattern, key):
    path = bank_dir / "bank.yaml"
    text, first, second = duplicate_line(path.read_text(), pattern)
    path.write_text(text)
    key = key or text.splitlines()[first - 1].split(":")[0].strip()
    with pytest.raises(BankError) as info:
        Bank.load(bank_dir)
    msg = str(info.value)
    assert msg.startswith(f"{path}:{second}:"), msg
    assert f"duplicate key {key!r}" in msg and f"lines {first} and {second}" in msg, msg
    assert main(["check", str(bank_dir)]) == 2
    err = capsys.readouterr().err
    assert f"duplicate key {key!r}" in err and str(path) in err


def test_map_with_a_repeated_phoneme_is_refused(tmp_path, capsys):
    flow = tmp_path / "flow.yaml"
    flow.write_text("name: dup\nsilence: X\nfallback: C\nmap: {AA: D, B: A, AA: B}\n")
    with pytest.raises(MapError, match=r"flow\.yaml:4: .*duplicate key 'AA' \(line 4, twice"):
        load_map(flow)
    block = tmp_path / "block.yaml"
    block.write_text("name: dup\nsilence: X\nfallback: C\nmap:\n  AA: D\n  B: A\n  AA: B\n")
    with pytest.raises(MapError, match=r"block\.yaml:7: .*duplicate key 'AA' \(lines 5 and 7"):
        load_map(block)
    phn = tmp_path / "a.phn"
    phn.write_text("0 1600 h#\n1600 4800 aa\n4800 8000 h#\n")
    assert main(["timeline", str(phn), "--map", str(block)]) == 2
    assert "duplicate key 'AA'" in capsys.readouterr().err


def test_merge_keys_still_override():
    # `<<` merges then lets the mapping's own keys win: not a duplicate
    assert _yaml.safe_load("base: &b {x: 1, y: 2}\nd:\n  <<: *b\n  x: 3\n")["d"] == {"x": 3, "y": 2}
    for loader in (_yaml.SafeLoader, _yaml.CSafeLoader):
        if loader is not None:
            with pytest.raises(_yaml.DuplicateKeyError):
                yaml.load("a: 1\nb: 2\na: 3\n", Loader=loader)
    # equal keys of different spellings are still equal keys
    with pytest.raises(_yaml.DuplicateKeyError, match="duplicate key 1"):
        _yaml.safe_load("1: a\n0x1: b\n")


keys = st.text(st.characters(whitelist_categories=("Ll", "Lu", "Nd"), max_codepoint=0x17F), min_size=1,
               max_size=6).filter(lambda k: not k.isdigit())
scalars = st.one_of(st.integers(-10**6, 10**6), st.floats(allow_nan=False, width=32), st.booleans(), st.none(),
                    st.text(max_size=12))
documents = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                          st.dictionaries(keys, inner, max_size=5)),
                         max_leaves=20)


@settings(max_examples=150, deadline=None)
@given(doc=st.dictionaries(keys, documents, min_size=1, max_size=6))
def test_documents_without_repeats_load_as_safe_load_loads_them(doc):
    for style in (False, True, None):
        text = yaml.safe_dump(doc, default_flow_style=style, allow_unicode=True, sort_keys=False)
        assert _yaml.safe_load(text) == yaml.safe_load(text)


@settings(max_examples=150, deadline=None)
@given(names=st.lists(keys, min_size=2, max_size=12, unique=True), data=st.data())
def test_a_repeated_key_anywhere_is_named_with_both_lines(names, data):
    # a block mapping (optionally nested one level) with the key at position i repeated at j
    i = data.draw(st.integers(0, len(names) - 2))
    j = data.draw(st.integers(i + 1, len(names) - 1))
    names = list(names)
    names[j] = names[i]
    nested = data.draw(st.booleans())
    indent = "  " if nested else ""
    lines = (["outer:"] if nested else []) + [f"{indent}{k!r}: {n}" for n, k in enumerate(names)]
    text = "\n".join(lines) + "\n"
    offset = 1 if nested else 0
    with pytest.raises(_yaml.DuplicateKeyError) as info:
        _yaml.safe_load(text)
    first, second = i + 1 + offset, j + 1 + offset
    assert info.value.problem_mark.line + 1 == second
    assert f"duplicate key {names[i]!r} (lines {first} and {second};" in info.value.problem
