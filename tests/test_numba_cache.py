"""contoursim's compiled functions are cached on disk and never loaded stale (contoursim/_numba.py)."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import contoursim

CALLER = "from contoursim._numba import njit\nfrom ._probe_callee import callee\n\n\n@njit(cache=True)\ndef caller():\n    return callee()\n"
CALLEE = "from contoursim._numba import njit\n\n\n@njit(cache=True)\ndef callee():\n    return {}\n"


def test_a_function_whose_callee_in_another_file_changed_is_compiled_afresh(tmp_path):
    """numba stamps a cached function with its own file's contents only; contoursim's are stamped with all its files.

    A copy of the package with a caller in one file and its callee in another: after the callee's file changes (a
    ``git pull`` or a reinstall in place that leaves the caller's file as it was), the caller returns the new value,
    not the one compiled into its cached code; with nothing changed, the caller is loaded from the cache.
    """
    package = tmp_path / "site" / "contoursim"
    shutil.copytree(Path(contoursim.__file__).parent, package, ignore=shutil.ignore_patterns("__pycache__"))
    (package / "_probe_caller.py").write_text(CALLER)
    env = dict(os.environ, PYTHONPATH=str(tmp_path / "site"), NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               NUMBA_DEBUG_CACHE="1")  # numba says on stdout what it loads from the cache and what it saves there
    run = [sys.executable, "-c", "from contoursim._probe_caller import caller; print(caller())"]
    seen = []
    for value in (1, 2, 2):
        (package / "_probe_callee.py").write_text(CALLEE.format(value))
        *said, answer = subprocess.run(run, env=env, cwd=tmp_path, capture_output=True, text=True,
                                       check=True).stdout.splitlines()
        loaded = any("data loaded" in line and "_probe_caller.caller" in line for line in said)
        seen.append((answer, loaded))
    assert seen == [("1", False), ("2", False), ("2", True)]
    assert any((tmp_path / "cache").rglob("_probe_caller.caller-*.nbc"))  # cached where NUMBA_CACHE_DIR says
