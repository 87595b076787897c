"""numba, as contoursim uses it: every module takes ``njit`` from here.

Compiled functions are cached on disk (``cache=True``). numba would put that
cache in the ``__pycache__`` folder beside the source, which for an installed
contoursim is inside ``site-packages``: files pip does not own, which outlive
an uninstall and leave an importable, empty ``contoursim`` behind. So the
cache of contoursim's own functions goes to the user-wide cache folder
instead (``~/.cache/numba`` on Linux, or ``NUMBA_CACHE_DIR`` when set);
other packages' functions are cached as numba always does.

numba tells a cached function stale by its own file's contents only, while
its compiled code holds what it calls from contoursim's other files (and
their constants): after a ``git pull`` or a reinstall in place that changed
a callee's file but not its caller's (``contour.py`` calls into
``nearest.py`` and ``paths.py``), the caller's old code was loaded, and with
it the old numbers, silently. The stamp of contoursim's cached functions is
the digest of all its source files instead: a version that differs in any
of them compiles afresh.

A first run (a cold cache) compiles them, ~20 s of CPU; :class:`CompileClock`
tells when that happens, so the command line can say so.
"""

import functools
import hashlib
import os
import time
from pathlib import Path

from numba import njit
from numba.core import config
from numba.core.caching import CacheImpl, UserWideCacheLocator
from numba.core.event import Listener

__all__ = ["CompileClock", "njit"]

_PACKAGE = Path(__file__).resolve().parent


@functools.cache
def _sources_digest():
    """The SHA-256 digest of contoursim's source files, their paths in the package and their contents."""
    digest = hashlib.sha256()
    for file in sorted(_PACKAGE.rglob("*.py")):
        digest.update(file.relative_to(_PACKAGE).as_posix().encode() + b"\0" + file.read_bytes() + b"\0")
    return digest.hexdigest()


class _PackageCacheLocator(UserWideCacheLocator):
    """``NUMBA_CACHE_DIR`` where set, else the user-wide cache folder, for functions defined in contoursim's own files
    only, stamped with all of them (:func:`_sources_digest`)."""

    def __init__(self, py_func, py_file):
        super().__init__(py_func, py_file)
        if config.CACHE_DIR:
            self._cache_path = os.path.join(config.CACHE_DIR, self.get_suitable_cache_subpath(py_file))

    def get_source_stamp(self):
        return _sources_digest()

    @classmethod
    def from_function(cls, py_func, py_file):
        if not Path(py_file).resolve().is_relative_to(_PACKAGE):
            return None
        return super().from_function(py_func, py_file)


class CompileClock(Listener):
    """A numba event listener timing the compilation of contoursim's functions.

    Install it with ``numba.core.event.install_listener("numba:compile", clock)``.
    Functions loaded from the cache do not compile and are not counted.

    Parameters
    ----------
    on_first : callable
        Called with no argument when the first of contoursim's functions starts compiling.

    Attributes
    ----------
    seconds : float
        Wall time spent compiling contoursim's functions so far [s] (callees counted once, in their caller).
    """

    def __init__(self, on_first):
        self.on_first, self.seconds, self._depth, self._since = on_first, 0.0, 0, None

    @staticmethod
    def _ours(event):
        return event.data["dispatcher"].py_func.__module__.startswith(__package__ + ".")

    def on_start(self, event):
        if not self._ours(event):
            return
        if self._depth == 0:
            if self._since is None:
                self.on_first()
            self._since = time.perf_counter()
        self._depth += 1

    def on_end(self, event):
        if not self._ours(event):
            return
        self._depth -= 1
        if self._depth == 0:
            self.seconds += time.perf_counter() - self._since


if _PackageCacheLocator not in CacheImpl._locator_classes:
    # Before numba's own locators (NUMBA_CACHE_DIR's, then the in-tree __pycache__), which stamp a file alone.
    CacheImpl._locator_classes.insert(0, _PackageCacheLocator)
