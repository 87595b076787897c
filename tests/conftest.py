from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data" / "real"


@pytest.fixture
def real_data():
    """The measured data folder beside the repository (../shared/data/real); skipped where absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"measured data not present at {SHARED_DATA} (it ships beside the repository, not in it)")
    return SHARED_DATA
