"""Numba for the library's compiled arithmetic, imported once, without SciPy on the flight path.

Numba imports SciPy (a version check; BLAS for `np.dot` and `np.linalg` in compiled code): that
would put SciPy on the flight path (`pd_core.runtime`). Where SciPy is not loaded already, numba
is imported here with SciPy hidden, so that process's compiled code has no BLAS (no kernel of the
runtime uses it).

- `njit`: numba's, for compiled functions (`cache=True` keeps their machine code in
  `__pycache__`).
- `jitable`: a plain Python function that numba compiles inline into any `njit` function calling
  it (`numba.extending.register_jitable`): one definition serves Python callers (teachers,
  benches) and compiled ones (the runtime layer's kernels).
- `drop_stale_cache`: numba's cache checks only the source file of the function it caches, not
  of the functions compiled into it; a cached kernel would keep flying an old `jitable` after an
  edit. Called before the kernels of a package are compiled, it removes their cache index where
  any source they depend on is newer, so the first process after an edit compiles them again.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from pathlib import Path

if "scipy" in sys.modules:
    from numba import njit
    from numba.extending import register_jitable as jitable
else:  # numba imports SciPy to check its version and to look for BLAS: neither is used here
    sys.modules["scipy"] = None  # type: ignore[assignment]  # "import scipy" fails
    try:
        import numba.np.arraymath  # noqa: F401  (its BLAS check, now rather than at a first call)
        from numba import njit
        from numba.extending import register_jitable as jitable
    finally:
        del sys.modules["scipy"]


def drop_stale_cache(cached: Iterable[Path], sources: Iterable[Path]) -> int:
    """Remove numba's cache index (`__pycache__/<stem>.*.nbi`) of the modules `cached` where it
    is older than any of `sources` (the modules themselves and what they compile in); returns
    how many were removed. Missing files are skipped (a cache another process just replaced)."""
    newest = max((p.stat().st_mtime for p in sources if p.exists()), default=0.0)
    removed = 0
    for module in cached:
        for index in (module.parent / "__pycache__").glob(f"{module.stem}.*.nbi"):
            try:
                if index.stat().st_mtime < newest:
                    index.unlink()
                    removed += 1
            except FileNotFoundError:
                continue
    return removed


__all__ = ["drop_stale_cache", "jitable", "njit"]
