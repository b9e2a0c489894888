"""saucerfab: design and fabricate mirror cup and saucer art.

The method is "Computational Mirror Cup and Saucer Art" (sections 3 and 4);
see ``ARCHITECTURE.md`` for the pipeline. Heavy parts (torch, numba, mesh
libraries) are imported lazily by the modules that need them, so importing
``saucerfab`` itself is cheap.
"""

__version__ = "0.1.0"

from saucerfab.errors import SaucerfabError  # noqa: E402

__all__ = ["SaucerfabError", "__version__"]
