import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data" / "real"


@pytest.fixture(scope="session", autouse=True)
def analysis_cache(tmp_path_factory):
    """Loop analyses stored in a folder of this session (and its subprocesses): the tests analyse, not read a user's store."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("CONTOURSIM_CACHE_DIR", str(tmp_path_factory.mktemp("contoursim_cache")))
        yield


@pytest.fixture
def real_data():
    """The measured data folder beside the repository (../shared/data/real).

    Where it is absent the test skips, saying where the data lives; in CI (the
    ``CI`` variable set) it fails instead, so a clone without the data cannot pass.
    """
    if not SHARED_DATA.is_dir():
        message = f"measured data not present at {SHARED_DATA}: it ships beside the repository, not in it"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    return SHARED_DATA


@pytest.fixture
def independent_truth(monkeypatch):
    """benchmarks/independent_truth.py: the hidden-effect trace generator written apart from contoursim."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import independent_truth

    return independent_truth


class ReaderGone:
    """A command's standard output whose reader stops after the first line, as ``contoursim ... | head -1``.

    Set it as ``sys.stdout`` in the test itself (pytest sets its own capture after the fixtures).
    """

    def __init__(self):
        self.text = ""

    def write(self, text):
        if "\n" in self.text:
            raise BrokenPipeError(32, "Broken pipe")
        self.text += text
        return len(text)

    def flush(self):
        pass
