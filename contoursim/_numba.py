"""numba, as contoursim uses it: every module takes ``njit`` from here.

Compiled functions are cached on disk (``cache=True``). numba would put that
cache in the ``__pycache__`` folder beside the source, which for an installed
contoursim is inside ``site-packages``: files pip does not own, which outlive
an uninstall and leave an importable, empty ``contoursim`` behind. So the
cache of contoursim's own functions goes to the user-wide cache folder
instead (``~/.cache/numba`` on Linux, or ``NUMBA_CACHE_DIR`` when set);
other packages' functions are cached as numba always does.
"""

from pathlib import Path

from numba import njit, prange
from numba.core.caching import CacheImpl, UserWideCacheLocator

__all__ = ["njit", "prange"]

_PACKAGE = Path(__file__).resolve().parent


class _PackageCacheLocator(UserWideCacheLocator):
    """The user-wide cache folder, for functions defined in contoursim's own files only."""

    @classmethod
    def from_function(cls, py_func, py_file):
        if not Path(py_file).resolve().is_relative_to(_PACKAGE):
            return None
        return super().from_function(py_func, py_file)


if _PackageCacheLocator not in CacheImpl._locator_classes:
    # After numba's own NUMBA_CACHE_DIR locator, before its in-tree (__pycache__) one.
    CacheImpl._locator_classes.insert(1, _PackageCacheLocator)
