"""saucerfab: design and fabricate mirror cup and saucer art.

The method is "Computational Mirror Cup and Saucer Art" (sections 3 and 4);
see ``ARCHITECTURE.md`` for the pipeline. Heavy parts (torch, numba, mesh
libraries) are imported lazily by the modules that need them, so importing
``saucerfab`` itself is cheap.
"""

import os as _os

__version__ = "0.1.0"

# torch's OpenMP workers spin-wait after each parallel region by default and
# would fight the numba kernels' threads for the two cores; passive waiting
# must be chosen before torch (and its OpenMP runtime) is loaded, and every
# entry point imports this package first. A user's own setting wins.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from saucerfab.errors import SaucerfabError  # noqa: E402

__all__ = ["SaucerfabError", "__version__"]
