"""The workflow: what happens to a design folder, written once for every front door.

``saucerfab export``, ``saucerfab design``'s verify, ``saucerfab batch`` and
the studio are thin doors over these functions; none of them calls a stage
(``export_design``, ``check_mesh``, ``verify_print``) itself
(``tests/test_workflow.py`` holds them to it).

- :func:`run_design`: a design request -> a design folder with its page, the typed
  :class:`~saucerfab.model.design.Design` returned (:mod:`.designing`);
- :func:`make_print`: a design folder -> a print folder: export, check every
  file, quick verify, ``report.html`` (:mod:`.printing`);
- :func:`finish_print`: the same after an export that exists;
- :func:`verify_design`: a design's quick verify through a trial export (:mod:`.quick_verify`);
- :func:`check_export`, :func:`meshes_to_check`, :func:`export_limits`: the check step (:mod:`.checks`).

The workflow may import the stage packages (``fabricate``, ``check``,
``verify``, ``report_page``, ``optimize``); they never import it
(``tests/test_layout.py``).
"""

from __future__ import annotations

from saucerfab.workflow.checks import CheckedFile, MeshToCheck, check_export, export_limits, meshes_to_check
from saucerfab.workflow.designing import design_pages, run_design
from saucerfab.workflow.printing import STAGES, PrintResult, finish_print, make_print
from saucerfab.workflow.quick_verify import QUICK_RES, QUICK_SPP, QUICK_TEXTURE_PX, quick_verify, verify_design

__all__ = [
    "QUICK_RES",
    "QUICK_SPP",
    "QUICK_TEXTURE_PX",
    "STAGES",
    "CheckedFile",
    "MeshToCheck",
    "PrintResult",
    "check_export",
    "design_pages",
    "export_limits",
    "finish_print",
    "make_print",
    "meshes_to_check",
    "quick_verify",
    "run_design",
    "verify_design",
]
