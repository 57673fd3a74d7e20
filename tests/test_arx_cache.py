"""The kernels' on-disk cache: one stamp for every kernel file (hcid.arx._cache).

numba invalidates a cached function when its own file changes; the engine's kernels
call each other across files, so each entry carries the hash of all of them.
"""

import pytest
from numba.core.dispatcher import Dispatcher

from hcid.arx import _blocks, _cache, _kernels, _lane_ir, _lanes


def _kernels_of(module):
    return [v for v in vars(module).values() if isinstance(v, Dispatcher) and v.__module__ == module.__name__]


@pytest.mark.parametrize("module", [_kernels, _lanes, _blocks, _lane_ir])
def test_every_kernel_is_stamped_with_all_kernel_files(module):
    kernels = _kernels_of(module)
    assert kernels
    for kernel in kernels:
        locator = kernel._cache._impl.locator
        assert isinstance(locator, _cache._InTree | _cache._UserProvided | _cache._UserWide), kernel
        own, together = locator.get_source_stamp()
        assert together == _cache.kernels_stamp()


def test_the_stamp_changes_with_any_kernel_file(tmp_path):
    # Source: the stamp is a SHA-256 over the files' contents; changing one file changes it.
    names = ("a.py", "b.py")
    for name in names:
        (tmp_path / name).write_text(f"# {name}\n")
    before = _cache.kernels_stamp(tmp_path, names)
    (tmp_path / "b.py").write_text("# b.py, edited\n")
    assert _cache.kernels_stamp(tmp_path, names) != before


def test_other_functions_keep_numbas_own_locators(tmp_path):
    # A function outside hcid/arx's kernel files is not ours to stamp.
    assert _cache._InTree.from_function(test_other_functions_keep_numbas_own_locators, __file__) is None


def test_a_read_only_package_falls_back_to_a_stamped_locator(monkeypatch):
    # Without a writable __pycache__ numba moves on to the user-wide folder: ours too, stamped.
    from numba.core import caching

    def unwritable(self):
        raise OSError("read-only")

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setattr(caching.config, "CACHE_DIR", "")
    monkeypatch.setattr(caching.InTreeCacheLocator, "ensure_cache_path", unwritable)
    monkeypatch.setattr(caching.UserWideCacheLocator, "ensure_cache_path", lambda self: None)
    kernel = _kernels.fit_units.py_func
    found = next(
        loc
        for cls in caching.CacheImpl._locator_classes
        if (loc := cls.from_function(kernel, _kernels.__file__)) is not None
    )
    assert isinstance(found, _cache._UserWide) and found.get_source_stamp()[1] == _cache.kernels_stamp()
