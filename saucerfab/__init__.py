"""saucerfab: design and fabricate mirror cup and saucer art.

The method is "Computational Mirror Cup and Saucer Art" (sections 3 and 4);
see ``ARCHITECTURE.md`` for the pipeline. Heavy parts (torch, numba, mesh
libraries) are imported lazily by the modules that need them, so importing
``saucerfab`` itself is cheap.
"""

import os as _os

__version__ = "0.1.0"

# torch's OpenMP (libgomp) workers spin-wait after each parallel region, by
# default for about 300,000 spins (milliseconds), and would fight the numba
# kernels' threads for the cores. Waiting passively (no spin) costs a wake-up
# per torch op instead; a short spin of GOMP_SPINCOUNT rounds (a fraction of a
# millisecond) bridges the gaps between one step's torch ops and then frees
# the cores: default designs took 7-14 % less time than with passive waiting
# alone (three pairs, two to six interleaved runs of each, issue 18, session
# 16: benchmarks/results/HISTORY.md, "The default design with less fixed
# cost"). Both must be chosen before torch (and its OpenMP
# runtime) is loaded, and every entry point imports this package first. A
# user's own setting of either wins.
if "OMP_WAIT_POLICY" not in _os.environ:
    _os.environ["OMP_WAIT_POLICY"] = "PASSIVE"
    _os.environ.setdefault("GOMP_SPINCOUNT", "20000")

from saucerfab.errors import SaucerfabError  # noqa: E402

#: the public Python API (what a notebook calls): name -> the module that defines it. Each is
#: imported on first use (PEP 562), so ``import saucerfab`` stays cheap and ``saucerfab check``
#: never loads torch. The README's "Python API" example uses them; tests/test_api.py runs it.
_API = {
    "DesignRequest": "saucerfab.optimize.request",
    "run_design": "saucerfab.workflow",
    "load_design": "saucerfab.model.design_folder",
    "Design": "saucerfab.model.design",
    "FabOptions": "saucerfab.fabricate.options",
    "export_design": "saucerfab.fabricate.pipeline",
    "ExportResult": "saucerfab.fabricate.pipeline",
    "verify_print": "saucerfab.verify.core",
    "check_mesh": "saucerfab.check",
    "load_profile": "saucerfab.model.profiles",
    "parse_eyes": "saucerfab.model.eyes",
}

__all__ = ["SaucerfabError", "__version__", *_API]


def __getattr__(name: str) -> object:
    """The public API's names, each imported from its module on first use."""
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'saucerfab' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # the next lookup is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
