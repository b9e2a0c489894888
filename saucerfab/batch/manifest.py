"""Batch manifests: the list of jobs a print bureau runs in one go.

A manifest is a TOML or a CSV file (chosen by its suffix). Each job has an
``id``, either a finished design folder (``design``) or the raw inputs of a
design run (``direct`` + ``reflected`` images, a ``shape``, a ``scene``...),
a ``printer`` profile, a ``cup_diameter_mm`` (both optional: left out, they
default as ``saucerfab design`` / ``saucerfab export`` default them), the export ``formats`` and
optional per-job overrides (``design_options`` for the design run,
``export_options`` for the export).

TOML::

    [defaults]                     # optional; every job inherits these keys
    printer = "j55"
    cup_diameter_mm = 80
    formats = ["3mf"]

    [[job]]
    id = "teapot"
    design = "designs/teapot"      # a design folder ...

    [[job]]
    id = "cat-rose"
    direct = "images/rose.png"     # ... or the inputs of a design run
    reflected = "images/cat.png"
    shape = "waves"                # built-in name, or a .png / .npy file
    printer = "bureau"
    formats = ["obj", "3mf"]
    design_options = { resolution = 40, image_size = 64, max_iters = 30 }

    [[job]]
    id = "round"                   # a round saucer, the cup at its centre
    direct = "images/rose.png"
    reflected = "images/cat.png"
    scene = "round"
    design_options = { saucer_diameter_mm = 180 }

CSV: one header row, then one row per job; columns are the job keys
(``id,design,direct,reflected,shape,scene,printer,cup_diameter_mm,formats,...``),
an empty cell means "not given", ``formats`` lists names separated by
spaces or ``;``, and ``design_options`` / ``export_options`` hold
``key=value`` pairs separated by ``;`` with TOML values
(``resolution=40; max_iters=50; ablation="full"``; a round saucer: ``scene`` ``round`` and
``saucer_diameter_mm=180``). Lines starting with ``#``
are comments.

Paths are relative to the manifest's folder and must stay inside it (after
resolving ``..`` and symbolic links); absolute paths are refused.

Checked when the manifest loads, before any work starts: syntax (alone, nothing
more can be read), nesting over :data:`~saucerfab.batch.manifest_lines.MAX_NESTING` deep, unknown keys or
columns, ids (valid, unique, not a name the batch writes), option names and
values (by the rules ``saucerfab design`` and ``export`` apply before their
work: :func:`_check_design_options`), formats, printer keys, paths leaving the
folder, and that every input file or design folder exists and can be read. A
manifest with any problem is refused as a whole, with every problem listed as
``m.toml:12: job 'id': ...`` (file and line: :mod:`saucerfab.batch.manifest_lines`).
What the files hold (a broken image, a bad design folder) is read when the
job runs: such a job fails on its own, and the others go on.
"""

from __future__ import annotations

import functools
import json
import os
import re
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from saucerfab.batch.manifest_lines import (
    MAX_NESTING,
    Problems,
    Report,
    Row,
    TomlLines,
    csv_records,
    input_problem,
    job_label,
    nesting_depth,
    read_manifest_text,
    reporter,
    resolve_inside,
    toml_loads,
)
from saucerfab.errors import ConfigError, SaucerfabError
from saucerfab.optimize.request import IMAGE_ROLES, TYPE_WORDS, DesignRequest, OptionsDoor

#: how a manifest's design_options are checked and worded: a manifest is fixed in an editor, so every
#: mistake is listed at once, with the manifest's key (tests/batch pins the messages)
MANIFEST_DOOR = OptionsDoor(
    words={**TYPE_WORDS, "str": "a string", "path": "a path"},
    text_max=None,
    finite=False,
    paths_as_text=False,
    all_at_once=True,
    unknown=lambda names, known: f"unknown design option(s) {sorted(names)}; allowed: {sorted(known)}",
    mistyped=lambda bad: "design_options: " + "; ".join(f"{n} must be {w}, got {v!r}" for n, w, v in bad),
    build_errors=(SaucerfabError, TypeError),
    build_prefix="design_options: ",
)

#: most jobs in one manifest
MAX_JOBS = 100_000
#: job ids name output folders: letters, digits, '.', '_', '-' (matched with
#: ``fullmatch``: ``$`` alone would also accept a trailing newline)
ID_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,79}")
#: names Windows keeps for devices, with or without an extension: no file or folder can have them
WINDOWS_DEVICES = frozenset({"CON", "PRN", "AUX", "NUL", "CONIN$", "CONOUT$",
                             *(f"{p}{i}" for p in ("COM", "LPT") for i in (*range(1, 10), "\u00b9", "\u00b2", "\u00b3"))})

#: what the batch itself writes in its output folder (saucerfab.batch.report, saucerfab.batch.runner)
JSON_NAME = "batch-report.json"
HTML_NAME = "batch-report.html"
LOCK_NAME = ".saucerfab-batch.lock"
SCRATCH_NAME = ".batch-tmp"

PATH_KEYS = ("design", *IMAGE_ROLES)
JOB_KEYS = frozenset(
    {
        "id",
        *PATH_KEYS,
        "shape",
        "scene",
        "cup",
        "printer",
        "cup_diameter_mm",
        "formats",
        "design_options",
        "export_options",
    }
)
SHAPE_SUFFIXES = (".png", ".npy")


def reserved_names() -> frozenset[str]:
    """Names the batch itself writes in its output folder, which no job id may take.

    A job folder named like a report would replace it (and every later write
    of the report would fail on the folder); the hidden names cannot match
    :data:`ID_RE` today, but are listed so that they stay reserved if it changes.
    """
    return frozenset({JSON_NAME, HTML_NAME, LOCK_NAME, SCRATCH_NAME})


def design_option_keys() -> frozenset[str]:
    """Fields of :class:`~saucerfab.optimize.request.DesignRequest` a job may override."""
    # printer and cup_diameter_mm are the job's own keys: the design is made for the
    # printer and size the job exports for (saucerfab.optimize.printable)
    taken = {*IMAGE_ROLES, "shape", "scene", "cup", "printer", "cup_diameter_mm"}
    return frozenset(f.name for f in fields(DesignRequest) if f.init and f.name not in taken)


@dataclass(frozen=True)
class JobSpec:
    """One job of a manifest, with its paths resolved (absolute, inside the manifest's folder).

    Attributes:
        id: unique name; also the name of the job's output folder.
        printer: a profile key (``j55``) or the absolute path of a profile TOML; None (a
            design folder's job without one): the printer the design was made for
            (:func:`saucerfab.batch.jobs.design_printer`), as ``saucerfab export``.
        cup_diameter_mm: physical cup width the print is scaled to, mm; None: the
            scene's (a design folder's own), as ``saucerfab design`` and ``export``.
        formats: export formats; empty means the printer's preferred format.
        design: a finished design folder, or None for a raw-input job.
        files: input files of a raw-input job by role (``direct``, ``reflected``,
            optional masks, ``shape`` and ``scene`` when they are files).
        shape: built-in base shape name when ``files`` has no ``shape``.
        scene: scene preset name when ``files`` has no ``scene``.
        cup: cup spec overriding the scene's (``circle:0.4``...), or None.
        design_options: DesignRequest fields overridden for this job.
        export_options: options passed to the export for this job.
        source: where the job is written (``manifest.toml:12``), for messages.
    """

    id: str
    printer: str | None
    cup_diameter_mm: float | None
    formats: tuple[str, ...] = ()
    design: Path | None = None
    files: dict[str, Path] = field(default_factory=dict)
    shape: str | None = None
    scene: str | None = None
    cup: str | None = None
    design_options: dict[str, Any] = field(default_factory=dict)
    export_options: dict[str, Any] = field(default_factory=dict)
    source: str = field(default="", compare=False)

    @property
    def kind(self) -> str:
        """``"design"`` for a design-folder job, ``"raw"`` for a job that designs first."""
        return "design" if self.design is not None else "raw"


@dataclass(frozen=True)
class Manifest:
    """A parsed manifest: its file, its folder (the root of every path) and its jobs."""

    path: Path
    root: Path
    jobs: tuple[JobSpec, ...]

    def job(self, job_id: str) -> JobSpec:
        for j in self.jobs:
            if j.id == job_id:
                return j
        raise KeyError(job_id)


def _looks_like_path(value: str, suffixes: tuple[str, ...]) -> bool:
    return "/" in value or "\\" in value or value.lower().endswith(suffixes)


def _options(value: Any, where: str) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: expected a table of options, got {value!r}")
    for k in value:
        if not isinstance(k, str) or not re.match(r"^[A-Za-z_][A-Za-z0-9_]*$", k):
            raise ConfigError(f"{where}: {k!r} is not a valid option name")
    return dict(value)


def id_problem(job_id: Any) -> str | None:
    """Why ``job_id`` cannot be a job's id (it names the job's output folder), or None."""
    if not isinstance(job_id, str) or not ID_RE.fullmatch(job_id):
        return (f"id {job_id!r} is missing or not a valid name; use 1-80 letters, digits, '.', '_' or '-', "
                "starting with a letter or digit (it names the job's output folder)")
    reserved = reserved_names()
    # case-insensitively: on macOS and Windows disks 'Batch-Report.JSON' is the report
    if job_id.casefold() in {n.casefold() for n in reserved}:
        return (f"id {job_id!r} is the name of a file the batch writes in its output folder "
                f"(reserved: {', '.join(sorted(reserved))}); give the job another id")
    if job_id.split(".")[0].upper() in WINDOWS_DEVICES or job_id.endswith("."):
        # a folder named CON, nul.txt or 'job.' cannot be made on Windows (a bureau's share, say): refuse
        # it on every system, so a manifest runs the same everywhere
        return (f"id {job_id!r} cannot name a folder on Windows (a device name such as CON, "
                "NUL, COM1 or LPT1, or a trailing '.'); give the job another id")
    return None


def _build_job(
    raw: dict[str, Any], root: Path, report: Report, printer_problem: Callable[[str], str | None], source: str,
    printer_accepts: Callable[[str], tuple[str, ...]] | None = None,
) -> JobSpec | None:
    """A :class:`JobSpec` from one job's plain data (defaults merged already), or None.

    Every problem is passed to ``report``, as many as the job has (one mistake
    does not hide the next); the job is None when there was any.
    ``printer_problem`` judges a printer key (cached per manifest).
    """
    from saucerfab.files.formats import FORMATS, WRITERS, lookup
    from saucerfab.model.scene import PRESETS

    found: list[str] = []

    def bad(key: str | None, message: str) -> None:
        found.append(message)
        report(key, message)

    def inside(key: str, value: Any) -> Path | None:
        """``value``, the path of input ``key``, resolved in the folder and checked to exist."""
        try:
            path = resolve_inside(root, value, key)
        except ConfigError as exc:
            bad(key, str(exc))
            return None
        problem = input_problem(path, value, key)
        if problem is not None:
            bad(key, problem)
            return None
        return path

    unknown = sorted(set(raw) - JOB_KEYS)
    if unknown:
        bad(unknown[0], f"unknown key(s) {unknown}; allowed: {sorted(JOB_KEYS)}")
    job_id = raw.get("id")
    problem = id_problem(job_id)
    if problem is not None:
        bad("id", problem)

    has_design = raw.get("design") not in (None, "")
    # left out: 'saucerfab design's printer for a design run; for a design folder, the printer it
    # was made for, which only its design.json knows (read when the job runs: jobs.design_printer)
    printer = raw.get("printer", None if has_design else DesignRequest.default("printer"))
    if printer is not None:
        if not isinstance(printer, str) or not printer.strip():
            bad("printer", f"'printer' must be a profile key (see 'saucerfab printers') or a .toml file, got "
                f"{printer!r}; leave it out for the default")
        elif _looks_like_path(printer, (".toml",)):
            path = inside("printer", printer)
            printer = None if path is None else str(path)
        elif (problem := printer_problem(printer)) is not None:
            bad("printer", problem)

    cup_mm = raw.get("cup_diameter_mm")  # left out: the scene's (a design folder's own), as design and export do
    if isinstance(cup_mm, str):
        try:
            cup_mm = float(cup_mm)
        except ValueError:
            pass
    if cup_mm is not None and (
        isinstance(cup_mm, bool) or not isinstance(cup_mm, (int, float)) or not (0 < cup_mm < 10_000)
    ):
        bad("cup_diameter_mm", f"'cup_diameter_mm' must be a positive number of millimetres, got {cup_mm!r}; "
            "leave it out for the scene's (a design folder's own)")

    formats_raw = raw.get("formats", ())
    if isinstance(formats_raw, str):
        formats_raw = [f for f in re.split(r"[\s;,|]+", formats_raw) if f]
    formats: tuple[str, ...] = ()
    if not isinstance(formats_raw, (list, tuple)) or not all(isinstance(f, str) for f in formats_raw):
        bad("formats", f"'formats' must be a list of format names, got {formats_raw!r}")
    else:
        # a name --formats takes (any case, a leading dot, an alias such as vrml) is the same here
        named = [(f, lookup(f)) for f in formats_raw]
        unknown = [f for f, fmt in named if fmt is None or fmt.key not in WRITERS]
        if unknown:
            bad("formats", f"unknown format(s) {unknown}; known: {list(FORMATS)}")
        formats = tuple(dict.fromkeys(fmt.key for _, fmt in named if fmt is not None))
    if formats and printer is not None and printer_accepts is not None and printer_problem(printer) is None:
        # the export's rule (fabricate.registry.normalize_formats), said at load instead of after a design run
        taken = printer_accepts(printer)
        if refused := [f for f in formats if f not in taken]:
            bad("formats", f"printer {printer!r} does not take {', '.join(f.upper() for f in refused)} (it takes "
                f"{', '.join(taken)}); list formats it takes")

    has_raw = any(raw.get(k) not in (None, "") for k in (*IMAGE_ROLES, "shape", "scene", "cup"))
    options: dict[str, dict[str, Any]] = {}
    for k in ("design_options", "export_options"):
        try:
            options[k] = _options(raw.get(k), k)
        except ConfigError as exc:
            bad(k, str(exc))
            options[k] = {}
    design_options, export_options = options["design_options"], options["export_options"]
    try:
        _check_export_options(export_options)
    except ConfigError as exc:
        bad("export_options", str(exc))
    if has_design and (has_raw or design_options):
        bad("design", "give either a design folder ('design') or the inputs of a design run "
            "(direct, reflected, shape, scene, cup, design_options), not both")
        return None
    common = dict(
        id=job_id,
        printer=printer,
        cup_diameter_mm=None if cup_mm is None else float(cup_mm),
        formats=formats,
        export_options=export_options,
        source=source,
    )
    if has_design:
        design = inside("design", raw["design"])
        return None if found else JobSpec(design=design, **common)  # type: ignore[arg-type]

    missing = [k for k in ("direct", "reflected") if raw.get(k) in (None, "")]
    if missing:
        bad(None, f"a job needs a design folder ('design') or both images of a design run; missing {missing}")
    files: dict[str, Path] = {}
    for k in IMAGE_ROLES:
        if raw.get(k) not in (None, "") and (path := inside(k, raw[k])) is not None:
            files[k] = path
    shape = raw.get("shape", DesignRequest.default("shape"))
    scene = raw.get("scene", DesignRequest.default("scene"))
    shape_name: str | None = None
    if not isinstance(shape, str) or not shape:
        bad("shape", f"'shape' must be a built-in shape name or a .png/.npy file, got {shape!r}")
    elif _looks_like_path(shape, SHAPE_SUFFIXES):
        if (path := inside("shape", shape)) is not None:
            files["shape"] = path
    else:
        from saucerfab.model.heightfield import BASE_SHAPES

        shape_name = shape
        if shape.replace("-", "_").lower() not in BASE_SHAPES:
            bad("shape", f"unknown base shape {shape!r}; built-in: {sorted(BASE_SHAPES)}, or a .png/.npy file")
    scene_name: str | None = None
    if not isinstance(scene, str) or not scene:
        bad("scene", f"'scene' must be a preset name or a .toml file, got {scene!r}")
    elif scene in PRESETS:
        scene_name = scene
    elif not _looks_like_path(scene, (".toml",)):
        bad("scene", f"scene {scene!r} is neither a preset {sorted(PRESETS)} nor a .toml file")
    elif (path := inside("scene", scene)) is not None:
        files["scene"] = path
    cup = raw.get("cup")
    if cup is not None and (not isinstance(cup, str) or not cup):
        bad("cup", f"'cup' must be a cup spec like 'circle:0.4', got {cup!r}")
        cup = None
    elif cup is not None:
        from saucerfab.model.cups import parse_cup_spec

        try:
            parse_cup_spec(cup)
        except ConfigError as exc:
            bad("cup", str(exc))
            cup = None
    try:  # placeholders for images with a problem of their own: only the options are judged here
        images = {k: files.get(k, Path(k)) for k in ("direct", "reflected")}
        _check_design_options(design_options, images, scene_name, cup)
    except ConfigError as exc:
        bad("design_options", str(exc))
    if found:
        return None
    return JobSpec(
        files=files,
        shape=shape_name,
        scene=scene_name,
        cup=cup,
        design_options=design_options,
        **common,  # type: ignore[arg-type]
    )


def _check_design_options(
    options: dict[str, Any], files: dict[str, Path], scene: str | None, cup: str | None
) -> None:
    """Refuse, at load, every design option ``saucerfab design`` would refuse before its work.

    The rules are the CLI's own, not copies: the option names are
    :func:`design_option_keys`, their types the :class:`DesignRequest` field
    annotations (argparse's ``type=`` on the command line) and the value checks
    ``DesignRequest``'s (with :func:`~saucerfab.optimize.stages.check_weights`: a
    weight no stage uses), all through :meth:`DesignRequest.from_options` (the
    studio's form goes through it too); the
    resolution and image-size ranges are those of the scene the run builds
    (:func:`~saucerfab.optimize.prepare.build_scene`, as the design's
    ``prepare`` does). A job with a scene *file* has its overrides checked on
    the paper preset's scene (the ranges do not depend on the scene) and
    its cup with the scene file when the job runs: the file is the job's
    input, read when the job runs, not when the manifest loads (so is a round
    saucer's ``saucer_diameter_mm`` with it: only a disc takes one).

    Raises:
        ConfigError: ``unknown design option(s) [...]; allowed: [...]``, else
            ``design_options: ...``: every mistyped option at once, else the first refused value.
    """
    from saucerfab.model.heightfield import check_height_scale

    request = DesignRequest.from_options(
        options, door=MANIFEST_DOOR, allowed=design_option_keys(),
        inputs={"direct": files["direct"], "reflected": files["reflected"]},
    )
    try:
        check_height_scale(request.height_scale)
    except SaucerfabError as exc:
        raise ConfigError(f"design_options: {exc}") from None
    if scene is None:
        # a scene file: its overrides are checked on the default scene, and a round saucer's diameter
        # (only for a disc) with the file's own outline when the job runs
        options = {k: v for k, v in options.items() if k != "saucer_diameter_mm"}
    scene, cup = (scene, cup) if scene is not None else (DesignRequest.default("scene"), None)
    try:
        key = json.dumps(options, sort_keys=True)
    except (TypeError, ValueError):  # a value JSON cannot hold (a TOML date): check it uncached
        problem = _scene_problem(scene, cup, options)
    else:
        problem = _scene_problem_cached(scene, cup, key)
    if problem is not None:
        raise ConfigError(f"design_options: {problem}")


def _scene_problem(scene: str, cup: str | None, options: dict[str, Any]) -> str | None:
    """Why the design run's scene (preset ``scene``, ``cup`` override) cannot be built
    with these design options, in the design's own words, or None when it can."""
    from saucerfab.optimize.prepare import build_scene

    try:
        build_scene(DesignRequest(direct=Path("direct"), reflected=Path("reflected"), scene=scene, cup=cup, **options))
    except SaucerfabError as exc:
        return str(exc)
    except TypeError as exc:  # a value of the wrong type the annotations let through
        return str(exc)
    return None


@functools.lru_cache(maxsize=256)
def _scene_problem_cached(scene: str, cup: str | None, options_json: str) -> str | None:
    """:func:`_scene_problem`, cached: building a scene takes milliseconds, a manifest
    may list 100,000 jobs, and most share their options through ``[defaults]``."""
    return _scene_problem(scene, cup, json.loads(options_json))


def export_option_keys() -> frozenset[str]:
    """Fields of :class:`~saucerfab.fabricate.options.FabOptions` a job may set."""
    from saucerfab.fabricate.options import FabOptions

    return frozenset(f.name for f in fields(FabOptions) if f.init)


def _check_export_options(options: dict[str, Any]) -> None:
    """Refuse export options ``saucerfab export`` would refuse (unknown names, bad values)."""
    from saucerfab.fabricate.options import FabOptions

    allowed = export_option_keys()
    unknown = set(options) - allowed
    if unknown:
        raise ConfigError(f"unknown export option(s) {sorted(unknown)}; allowed: {sorted(allowed)}")
    try:
        FabOptions(**options)
    except (ConfigError, TypeError) as exc:
        raise ConfigError(f"export_options: {exc}") from None


def _merge(defaults: dict[str, Any], job: dict[str, Any]) -> dict[str, Any]:
    out = dict(defaults)
    # a job that names its own design folder does not inherit design-run inputs, and vice versa
    if job.get("design") not in (None, ""):
        for k in (*IMAGE_ROLES, "shape", "scene", "cup", "design_options"):
            out.pop(k, None)
    elif any(job.get(k) not in (None, "") for k in IMAGE_ROLES):
        out.pop("design", None)
    for k, v in job.items():
        if k in ("design_options", "export_options") and isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = {**out[k], **v}
        else:
            out[k] = v
    return out


def _toml_rows(path: Path, text: str, problems: Problems) -> tuple[dict[str, Any], list[Row], TomlLines]:
    """``[defaults]`` and the jobs of a TOML manifest; its structural mistakes go to ``problems``."""
    data = toml_loads(text, f"manifest {str(path)!r}")
    lines = TomlLines(text)
    unknown = sorted(set(data) - {"defaults", "job", "batch"})
    if unknown:
        problems.add(lines.top_keys.get(unknown[0]), "", f"unknown top-level key(s) {unknown}; "
                     "use [defaults], [[job]] (and optionally [batch] version = 1)")
    batch = data.get("batch", {})
    if not isinstance(batch, dict) or set(batch) - {"version"} or batch.get("version", 1) != 1:
        problems.add(lines.top_keys.get("batch"), "[batch]", f"may only hold version = 1, got {batch!r}")
    defaults = data.get("defaults", {})
    if not isinstance(defaults, dict):
        problems.add(lines.defaults(), "[defaults]", "must be a table of job keys ([defaults] then printer = ...)")
        defaults = {}
    defaults = dict(defaults)
    if defaults.pop("id", None) is not None:
        problems.add(lines.defaults("id"), "[defaults]", "cannot set 'id' (each job has its own): remove it")
    unknown = sorted(set(defaults) - JOB_KEYS)
    if unknown:  # listed once here, not once per job that inherits them
        problems.add(lines.defaults(unknown[0]), "[defaults]", f"unknown key(s) {unknown}; allowed: {sorted(JOB_KEYS)}")
        defaults = {k: v for k, v in defaults.items() if k in JOB_KEYS}
    jobs = data.get("job", [])
    if not isinstance(jobs, list) or not all(isinstance(j, dict) for j in jobs):
        problems.add(lines.top_keys.get("job"), "", "jobs are written as [[job]] tables")
        jobs = []
    return defaults, [(functools.partial(lines.job, i, len(jobs)), j) for i, j in enumerate(jobs)], lines


def parse_options_cell(cell: str, where: str) -> dict[str, Any]:
    """``"a=1; b=true; c=\\"x\\""`` -> ``{"a": 1, "b": True, "c": "x"}`` (TOML values; bare words are strings)."""
    out: dict[str, Any] = {}
    for part in cell.split(";"):
        part = part.strip()
        if not part:
            continue
        if "=" not in part:
            raise ConfigError(f"{where}: {part!r} is not key=value")
        k, v = (s.strip() for s in part.split("=", 1))
        try:
            out[k] = tomllib.loads(f"v = {v}")["v"]
        except tomllib.TOMLDecodeError:
            out[k] = v
        except RecursionError:  # see toml_loads
            raise ConfigError(f"{where}: the value of {k!r} nests arrays or tables too deeply to be read") from None
        if nesting_depth(out[k]) > MAX_NESTING:
            raise ConfigError(
                f"{where}: the value of {k!r} nests arrays or tables over {MAX_NESTING} levels deep; remove the nesting"
            )
    return out


def _csv_rows(path: Path, text: str, problems: Problems) -> list[Row]:
    """The jobs of a CSV manifest; its mistakes (columns, cells) go to ``problems``."""
    records = (r for r in csv_records(text) if any(c.strip() for c in r[1]))  # blank lines say nothing
    header_line, header = next(records, (0, []))
    if not header:
        raise ConfigError(f"manifest {str(path)!r} is empty; the first row names the columns (id,design,...)")
    names = [h.strip() for h in header]
    unknown = sorted(set(names) - JOB_KEYS)
    if unknown:  # listed once, at the header; their cells are left out of every row
        problems.add(header_line, "", f"unknown column(s) {unknown}; allowed: {sorted(JOB_KEYS)}")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        problems.add(header_line, "", f"column(s) {twice} given twice: keep one of each")
    rows: list[Row] = []
    id_at = names.index("id") if "id" in names else len(names)
    for number, (line, cells) in enumerate(records, start=1):
        label = job_label(cells[id_at].strip() if id_at < len(cells) else None, number)
        if len(cells) > len(names):
            problems.add(line, label, f"{len(cells)} cells but {len(names)} columns: quote a cell that holds a comma")
            continue
        job: dict[str, Any] = {}
        for k, v in zip(names, cells):
            v = v.strip()
            if not v or k not in JOB_KEYS:
                continue
            try:
                job[k] = parse_options_cell(v, k) if k in ("design_options", "export_options") else v
            except ConfigError as exc:
                problems.add(line, label, str(exc))
        rows.append((lambda key, line=line: line, job))
    return rows


def load_manifest(path: str | os.PathLike[str]) -> Manifest:
    """Read, validate and resolve a manifest (``.toml`` or ``.csv``).

    Raises:
        ConfigError: listing every problem found, each with the manifest's
            file name and line (``m.toml:12: job 'x': ...``): bad syntax (alone:
            nothing more can be read), unknown keys, duplicate ids, input files
            missing or leaving the manifest's folder, unknown printers, bad values.
    """
    from saucerfab.model.profiles import load_profile

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".csv"):
        raise ConfigError(f"manifest {str(path)!r}: use a .toml or .csv file")
    text = read_manifest_text(path)
    root = path.resolve().parent
    problems = Problems(path)
    if suffix == ".toml":
        defaults, rows, lines = _toml_rows(path, text, problems)
        defaults_line: Callable[[str | None], int | None] = lines.defaults
    else:  # CSV has no defaults
        defaults, rows, defaults_line = {}, _csv_rows(path, text, problems), lambda key: None
    if len(rows) > MAX_JOBS:
        raise ConfigError(f"manifest {str(path)!r} lists {len(rows)} jobs; at most {MAX_JOBS}, split it")
    if not rows and not len(problems):
        problems.add(None, "", "lists no jobs: add [[job]] tables (TOML) or rows (CSV)")

    @functools.cache  # per manifest: profiles are read once, not once per job
    def printer_problem(key: str) -> str | None:
        try:
            load_profile(key)
        except SaucerfabError as exc:
            return str(exc)
        return None

    @functools.cache
    def printer_accepts(key: str) -> tuple[str, ...]:
        return load_profile(key).accepted_formats

    jobs: list[JobSpec] = []
    seen: dict[str, str] = {}
    for number, (locate, own) in enumerate(rows, start=1):
        raw = _merge(defaults, own)
        report = reporter(problems, own, defaults, locate, defaults_line, job_label(raw.get("id"), number))
        job_id, twice = raw.get("id"), False
        if isinstance(job_id, str) and job_id:
            folded = job_id.lower()  # output folders must not collide on case-insensitive disks
            twice = folded in seen
            if twice:
                report("id", f"id {job_id!r} is used twice (also {seen[folded]}); ids name output folders: "
                       "give each job its own")
            else:
                seen[folded] = f"{path.name}:{locate('id')}"
        job = _build_job(raw, root, report, printer_problem, f"{path.name}:{locate(None)}", printer_accepts)
        if job is not None and not twice:
            jobs.append(job)
    if len(problems):
        raise problems.error()
    return Manifest(path=path.resolve(), root=root, jobs=tuple(jobs))

