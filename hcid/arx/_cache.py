"""numba's on-disk cache of the engine's kernels, invalidated by a change of any kernel file (private).

numba stamps a cached function with the hash of its own source file only: a kernel
that calls a kernel of another file, or inlines an intrinsic from one, would keep
its stale compiled copy after that other file changed. The kernels are spread over
:data:`KERNEL_FILES` (no module above 600 lines), so their cache entries carry one
stamp for all of them: a change to any kernel file recompiles every kernel.

Built on numba's cache locators (``numba.core.caching``, the version the lock file
pins); :func:`install` runs before any kernel is decorated (each kernel module
imports this one first).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from numba.core import caching

__all__ = ["KERNEL_FILES", "install", "kernels_stamp"]

_HERE = Path(__file__).resolve().parent
#: The files whose kernels call each other: one cache stamp for all of them.
KERNEL_FILES = ("_kernels.py", "_lane_ir.py", "_lanes.py", "_blocks.py", "_cache.py")


def kernels_stamp(folder: Path = _HERE, names: tuple[str, ...] = KERNEL_FILES) -> str:
    """SHA-256 of the kernel files' contents, in :data:`KERNEL_FILES` order."""
    h = hashlib.sha256()
    for name in names:
        h.update(name.encode())
        h.update((folder / name).read_bytes())
    return h.hexdigest()


_STAMP = kernels_stamp()


class _AllKernelFiles:
    """A locator for the kernel files only, stamping their entries with :func:`kernels_stamp`."""

    @classmethod
    def from_function(cls, py_func, py_file):
        path = Path(py_file).resolve()
        if path.parent != _HERE or path.name not in KERNEL_FILES:
            return None
        return super().from_function(py_func, py_file)

    def get_source_stamp(self):
        return (super().get_source_stamp(), _STAMP)


class _UserProvided(_AllKernelFiles, caching.UserProvidedCacheLocator):
    """``NUMBA_CACHE_DIR`` when set."""


class _InTree(_AllKernelFiles, caching.InTreeCacheLocator):
    """``hcid/arx/__pycache__`` otherwise."""


class _UserWide(_AllKernelFiles, caching.UserWideCacheLocator):
    """The user's cache folder when ``hcid/arx/__pycache__`` is not writable (an installed package)."""


def install() -> None:
    """Put the kernel locators first in numba's list (once; other functions are unaffected).

    Every place numba could cache a kernel (a set cache folder, the package's
    ``__pycache__``, the user's cache folder) has a locator here, so no kernel is
    cached with numba's own one-file stamp.
    """
    classes = caching.CacheImpl._locator_classes
    for locator in (_UserWide, _InTree, _UserProvided):
        if locator not in classes:
            classes.insert(0, locator)


install()
