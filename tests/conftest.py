import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

import synthetic  # noqa: E402


@pytest.fixture(scope="session")
def synthetic_bank_dir(tmp_path_factory):
    """A bank of the synthetic ellipse subject (see tests/synthetic.py)."""
    return synthetic.write_bank(tmp_path_factory.mktemp("synthetic") / "bank")
