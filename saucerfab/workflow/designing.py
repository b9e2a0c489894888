"""A :class:`~saucerfab.optimize.request.DesignRequest` -> a design folder with its page: :func:`run_design`.

The optimizer (:func:`saucerfab.optimize.pipeline.optimize_design`) makes
the design and writes its folder; the workflow adds the design's
``report.html`` (:mod:`saucerfab.pages.folder_pages`), written with the
folder in the same atomic step, so the stage below draws no page and the
pages never sit under the optimizer. Every front door (``saucerfab design``,
batch, the studio) and a notebook call this, and get the typed
:class:`~saucerfab.model.design.Design` back: its ``intent`` is what the
later steps (:func:`~saucerfab.workflow.make_print`,
:func:`~saucerfab.workflow.verify_design`) default from.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from saucerfab.model.design import Design
    from saucerfab.optimize.looks import Look
    from saucerfab.optimize.pipeline import Progress
    from saucerfab.optimize.request import DesignRequest


def design_pages(design: Design, previews: Mapping[str, bytes]) -> dict[str, bytes]:
    """The pages written with a design folder: ``report.html`` (UTF-8), by file name."""
    from saucerfab.pages.folder_pages import REPORT_NAME, design_report

    return {REPORT_NAME: design_report(design, previews).encode("utf-8")}


def run_design(
    request: DesignRequest,
    out: str | Path,
    *,
    progress: Progress | None = None,
    log_every_s: float = 2.0,
    look: Look | None = None,
) -> Design:
    """Design ``request`` into the folder ``out`` (written atomically, with its page); return the design.

    Args and errors as :func:`saucerfab.optimize.pipeline.optimize_design`
    (``progress`` about every ``log_every_s`` seconds, ``look`` after each
    look); the returned design's ``folder`` is ``out``.
    """
    from saucerfab.optimize.pipeline import optimize_design

    return optimize_design(request, out, progress=progress, log_every_s=log_every_s, look=look,
                           pages=design_pages)
