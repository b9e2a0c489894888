"""The design optimizer (paper, sections 3.1-3.5): energies, DR solver, stages, texturing.

Entry point: :func:`saucerfab.optimize.pipeline.optimize_design` (through the workflow's
:func:`saucerfab.workflow.run_design`, which adds the page) with a
:class:`saucerfab.optimize.request.DesignRequest`. torch is imported by the
modules that need it, not here.
"""

from saucerfab.optimize.request import DesignRequest

__all__ = ["DesignRequest"]
