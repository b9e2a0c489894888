"""The workflow's verify step: a quick ray trace of a print folder, or of a design through a trial export.

:func:`quick_verify` renders the first textured file of an export folder
from the design eye and a viewer's two eyes (:data:`QUICK_RES`,
:data:`QUICK_SPP`), pictures and ``verify.json`` in a ``verify/`` folder
replaced as a whole. :func:`verify_design` does the same for a design folder
through a trial export (``saucerfab design``'s verify, and the studio's).
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from saucerfab.model.profiles import DEFAULT_PRINTER

if TYPE_CHECKING:
    from saucerfab.model.design import Design

#: quick verify of every export: render size (pixels) and samples per pixel
QUICK_RES = 128
QUICK_SPP = 4

#: atlas edge (pixels) of the trial export a design's quick verify renders (:func:`verify_design`). At
#: QUICK_RES a view's frame spans 128 px, so 1024 texels across the saucer's top are several per
#: pixel; the printer's own atlas (4096 for a J55 at 600 dpi) costs a 16x larger bake and texture
#: load for the same picture (heart-star: 5.2 -> 2.1 s a quick verify,
#: benchmarks/results/HISTORY.md, "The quick verify of `saucerfab design`").
#: An export's own verify (:func:`~saucerfab.workflow.printing.finish_print`) always renders the atlas it wrote.
QUICK_TEXTURE_PX = 1024

#: ``progress(message, fraction)``: fraction in [0, 1]
Progress = Callable[[str, float], None]


def quick_verify(
    print_dir: Path,
    verify_dir: Path,
    *,
    record_times: bool = True,
    progress: Progress | None = None,
    spp: int = QUICK_SPP,
    light: Any = None,
    eyes: Any = None,
    **extra: Any,
) -> Any:
    """Quick-verify the print in ``print_dir``; pictures and ``verify.json`` into ``verify_dir`` (replaced whole).

    ``extra``: fields added to ``verify.json`` (``folder``, how the document
    names the print, defaults to ``"."``: the folder may be moved or sent on).
    ``record_times``: keep wall times (seconds) in ``verify.json``. ``spp``,
    ``light`` (a :class:`~saucerfab.verify.lighting.LightSpec`; None: emitted)
    and ``eyes`` (an :class:`~saucerfab.model.eyes.EyeSpec`; None: verify's
    default) as ``verify_print`` takes them (the studio's view under the room
    light). Returns the :class:`~saucerfab.verify.VerifyResult`.

    Raises:
        SaucerfabError: the print cannot be verified.
    """
    from saucerfab.files.fileio import atomic_dir
    from saucerfab.verify import verify_print

    chosen = {k: v for k, v in (("light", light), ("eyes", eyes)) if v is not None}
    with atomic_dir(verify_dir) as tmp:
        res = verify_print(print_dir, res=QUICK_RES, spp=spp, pictures_dir=tmp, all_formats=False,
                           progress=progress, **chosen)
        doc = res.to_dict(record_times=record_times)
        doc.update({"folder": ".", **extra})
        (tmp / "verify.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return res


def verify_design(
    design: Design | str | Path,
    *,
    printer: str | None = None,
    cup_diameter_mm: float | None = None,
    record_times: bool = True,
    progress: Progress | None = None,
) -> Any:
    """Quick-verify a design through a trial export; results in its folder's ``verify/``.

    ``design`` is a :class:`~saucerfab.model.design.Design` with its folder (what
    :func:`~saucerfab.workflow.run_design` returns) or a design folder; ``printer`` None is the
    printer it was made for (its :attr:`~saucerfab.model.design.Design.intent`), else
    :data:`~saucerfab.model.profiles.DEFAULT_PRINTER`.

    The design is exported (OBJ, or the first format verify renders that ``printer`` takes, with a
    :data:`QUICK_TEXTURE_PX` atlas) to a temporary folder, that print is verified as an export's is
    (:func:`quick_verify`), the pictures and ``verify.json`` (with the printer named) go into the design
    folder's ``verify/`` (replaced as a whole) and its ``report.html`` is rewritten with them. Returns the
    :class:`~saucerfab.verify.VerifyResult`.

    Raises:
        SaucerfabError: the trial export or the verify cannot be made.
    """
    # the module, not the function: tests replace pipeline.export_design to watch what is asked
    import saucerfab.fabricate.pipeline as pipeline
    from saucerfab.errors import ExportError
    from saucerfab.fabricate.options import FabOptions
    from saucerfab.files.formats import WRITERS
    from saucerfab.model.design import Design
    from saucerfab.model.design_folder import load_design
    from saucerfab.model.profiles import load_profile
    from saucerfab.pages.folder_pages import write_design_report
    from saucerfab.verify.printfolder import RENDERED_FORMATS

    if not isinstance(design, Design):
        design = load_design(design)
    if design.folder is None:
        raise ExportError("verify_design needs a design with its folder (the verify is written into it); "
                          "save the design first (saucerfab.model.design_folder.save_design)")
    design_dir = design.folder
    profile = load_profile(printer or design.intent.printer or DEFAULT_PRINTER)
    # the trial print in a format verify renders and the printer takes (OBJ first: the quickest to read)
    rendered = [f for f in RENDERED_FORMATS if f in WRITERS]  # ("zip" is how verify reads a zipped OBJ)
    fmt = next((f for f in rendered if f in profile.accepted_formats), None)
    if fmt is None:
        raise ExportError(f"{profile.name} takes none of {', '.join(rendered)}, the formats verify renders")
    with tempfile.TemporaryDirectory(prefix="saucerfab-trial-") as tmp:
        trial = pipeline.export_design(design, Path(tmp) / "print", printer=profile,
                                       cup_diameter_mm=cup_diameter_mm, formats=[fmt],
                                       options=FabOptions(texture_px=QUICK_TEXTURE_PX))
        res = quick_verify(trial.out, design_dir / "verify", record_times=record_times, progress=progress,
                           folder="(a trial export of this design)", printer=trial.printer,
                           cup_diameter_mm=trial.cup_diameter_mm, texture_px=QUICK_TEXTURE_PX)
    write_design_report(design_dir)
    return res
