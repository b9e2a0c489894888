"""numba where it is installed, plain Python where not: the checker runs on the base install.

numba comes with the ``design`` extra (:data:`saucerfab.extras.EXTRAS`), not
with ``pip install saucerfab`` (numba and llvmlite take about 210 MiB, more
than the rest of the checker's install). The checker's numba code is of two kinds:

* fast paths beside a numpy reference that gives the same answers (the BVH
  pair search, the exact pair test and the union-find of meshes from 200,000
  triangles; the OBJ and 3MF bulk parsers of files from 8 and 24 MB): a caller
  takes the fast path only when :func:`have_numba`, else the reference reads
  every size, slower on large meshes (a 360,000-triangle STL: 5.6-5.8 s
  instead of 3.8 s for ``saucerfab check``, load 1);
* the meshopt decoder's kernels, which have no numpy reference (a byte-by-byte
  walk whose steps depend on the bytes read): :func:`njit` leaves them as the
  Python they are written in, which decodes the same bytes some 300 times
  slower (100,096 vertices of 12 bytes: 0.95 s instead of 3 ms).

With numba installed nothing changes: :func:`njit` is ``numba.njit``. A CI job
that checks large files installs numba beside the checker (``pip install
saucerfab numba``) for the fast paths without torch.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any, TypeVar

from saucerfab.extras import installed

F = TypeVar("F", bound=Callable[..., Any])


def have_numba() -> bool:
    """Whether numba is installed (found without importing it: the import alone takes ~0.7 s)."""
    return installed("numba")


def numba_started() -> bool:
    """Whether numba's CPU compiler has started in this process (a kernel compiled or loaded from its cache).

    Starting it (LLVM and numba's CPU target) takes about 0.3-0.4 s once per
    process; after that, loading one more cached kernel takes milliseconds. A
    reader with a numpy path and a numba path for the same input can take
    the numba one for smaller inputs when this is true. numba makes its
    target context on first use; should that attribute ever be renamed, this
    answers False, which only keeps the cold-process choice
    (``tests/check/test_check_obj_fast.py`` pins it).
    """
    registry = sys.modules.get("numba.core.registry")
    target = getattr(registry, "cpu_target", None)
    return target is not None and "_toplevel_target_context" in vars(target)


def njit(**options: Any) -> Callable[[F], F]:
    """``numba.njit(**options)`` when numba is installed; else a decorator that leaves the function as Python."""
    if have_numba():
        import numba

        return numba.njit(**options)  # type: ignore[no-any-return]
    return lambda fn: fn
