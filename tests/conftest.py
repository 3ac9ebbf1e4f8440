import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

import synthetic  # noqa: E402


@pytest.fixture(scope="session", autouse=True)
def _own_cache_home(tmp_path_factory):
    """``$XDG_CACHE_HOME`` of this session (of each xdist worker): a folder of its own.

    Dubs without ``--cache`` and batch workers keep entries under it (the dub cache, unpacked
    banks). The user's ``~/.cache`` would make a run depend on what earlier runs left there
    (a warm cache hides work CI's clean machine does), fill it with test entries, and let two
    workers race on the same entries; subprocesses inherit the variable.
    """
    old = os.environ.get("XDG_CACHE_HOME")
    os.environ["XDG_CACHE_HOME"] = str(tmp_path_factory.mktemp("xdg-cache"))
    yield
    if old is None:
        os.environ.pop("XDG_CACHE_HOME", None)
    else:
        os.environ["XDG_CACHE_HOME"] = old


@pytest.fixture(scope="session")
def synthetic_bank_dir(tmp_path_factory):
    """A bank of the synthetic ellipse subject (see tests/synthetic.py)."""
    return synthetic.write_bank(tmp_path_factory.mktemp("synthetic") / "bank")


#: The files that take longest, heaviest first (CPU seconds, the test process and its
#: children, in a two-worker run of 2026-11-28). ``make test`` runs files whole on two workers
#: (``--dist loadfile --no-loadscope-reorder``) and hands them out in collection order: with
#: these first, the short files fill in around them at the end instead of one long file
#: running alone on one core after the other worker has finished (that run: doc examples
#: last, 157 s). A file missing from this list only costs time.
HEAVY_FIRST = (
    "test_doc_examples.py",       # 157 s: builds the wheel, runs every documented example
    "test_fuzz.py",               # 59 s: every reader, loader and server route fuzzed
    "test_dub_hardening.py",      # 55 s: real dubs, one SIGKILLed while it builds its bank
    "test_dub_lang.py",           # 43 s: dubs and inits in Spanish and French
    "test_plain_scripts.py",      # 43 s
    "test_dub.py",                # 34 s
    "test_batch.py",              # 34 s: dask clusters
    "test_align_cli.py",          # 30 s
    "test_crash_safety.py",       # 26 s
    "test_align_accuracy.py",     # 24 s
    "test_videobank.py",          # 22 s
)


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(HEAVY_FIRST)}
    # sorted() is stable: within a file, and among the other files, the order stays as collected
    items[:] = sorted(items, key=lambda item: rank.get(item.path.name, len(rank)))
