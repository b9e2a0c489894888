"""Batch manifests: the list of jobs a print bureau runs in one go.

A manifest is a TOML or a CSV file (chosen by its suffix). Each job has an
``id``, either a finished design folder (``design``) or the raw inputs of a
design run (``direct`` + ``reflected`` images, a ``shape``, a ``scene``...),
a ``printer`` profile, a ``cup_diameter_mm``, the export ``formats`` and
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

CSV: one header row, then one row per job; columns are the job keys
(``id,design,direct,reflected,shape,scene,printer,cup_diameter_mm,formats,...``),
an empty cell means "not given", ``formats`` lists names separated by
spaces or ``;``, and ``design_options`` / ``export_options`` hold
``key=value`` pairs separated by ``;`` with TOML values
(``resolution=40; max_iters=50; ablation="full"``). Lines starting with ``#``
are comments.

Paths are relative to the manifest's folder and must stay inside it (after
resolving ``..`` and symbolic links); absolute paths are refused. A manifest
with a structural mistake (bad syntax, nesting over :data:`MAX_NESTING` deep,
unknown key, duplicate id, an id the batch's own files use, a bad option
value, a path leaving the folder) is refused as a whole, with every problem
listed, before any work starts; option values are judged by the rules
``saucerfab design`` applies before its work (:func:`_check_design_options`).
A job whose files are missing or unreadable fails on its own when the batch
runs.
"""

from __future__ import annotations

import csv
import functools
import io
import json
import os
import re
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from saucerfab.errors import ConfigError
from saucerfab.optimize.request import IMAGE_ROLES, DesignRequest

#: largest manifest file accepted (a manifest is text listing jobs)
MAX_MANIFEST_BYTES = 16 * 1024 * 1024
#: most jobs in one manifest
MAX_JOBS = 100_000
#: job ids name output folders: letters, digits, '.', '_', '-' (matched with
#: ``fullmatch``: ``$`` alone would also accept a trailing newline)
ID_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,79}")
#: names Windows keeps for devices, with or without an extension: no file or folder can have them
WINDOWS_DEVICES = frozenset({"CON", "PRN", "AUX", "NUL", "CONIN$", "CONOUT$",
                             *(f"{p}{i}" for p in ("COM", "LPT") for i in (*range(1, 10), "\u00b9", "\u00b2", "\u00b3"))})
#: deepest nesting of arrays and tables a manifest may hold; a manifest needs 5
#: (the document, ``[[job]]``, a job, its ``design_options``, a list in it), and
#: neither the parser nor any later walk of the data may run out of stack
MAX_NESTING = 32

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
        printer: a profile key (``j55``) or the absolute path of a profile TOML.
        cup_diameter_mm: physical cup width the print is scaled to.
        formats: export formats; empty means the printer's preferred format.
        design: a finished design folder, or None for a raw-input job.
        files: input files of a raw-input job by role (``direct``, ``reflected``,
            optional masks, ``shape`` and ``scene`` when they are files).
        shape: built-in base shape name when ``files`` has no ``shape``.
        scene: scene preset name when ``files`` has no ``scene``.
        cup: cup spec overriding the scene's (``circle:0.4``...), or None.
        design_options: DesignRequest fields overridden for this job.
        export_options: options passed to the export for this job.
        source: where the job is written (``manifest.toml job #3``), for messages.
    """

    id: str
    printer: str
    cup_diameter_mm: float
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


def resolve_inside(root: Path, value: Any, where: str) -> Path:
    """``value`` (a relative path string) resolved against ``root``; refuse escapes.

    Raises:
        ConfigError: not a string, absolute, or resolving (``..``, symlinks) outside ``root``.
    """
    if not isinstance(value, str) or not value.strip():
        raise ConfigError(f"{where}: expected a relative path (a non-empty string), got {value!r}")
    p = Path(value)
    if p.is_absolute() or value.startswith(("/", "\\")) or re.match(r"^[A-Za-z]:", value):
        raise ConfigError(
            f"{where}: {value!r} is an absolute path; paths in a manifest are relative to its "
            f"folder {str(root)!r} and must stay inside it: move the file there and give it relative"
        )
    root_real = root.resolve()
    full = (root_real / p).resolve()
    if not full.is_relative_to(root_real):
        raise ConfigError(
            f"{where}: {value!r} resolves to {str(full)!r}, outside the manifest's folder "
            f"{str(root_real)!r}; manifest paths may not leave that folder (no '..' or links out): "
            "copy the file under it"
        )
    return full


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


def _build_job(raw: dict[str, Any], root: Path, where: str) -> JobSpec:
    """A :class:`JobSpec` from one job's plain data (defaults merged already)."""
    from saucerfab.formats import FORMATS, WRITERS, lookup
    from saucerfab.scene import PRESETS

    unknown = set(raw) - JOB_KEYS
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {sorted(unknown)}; allowed: {sorted(JOB_KEYS)}")
    job_id = raw.get("id")
    if not isinstance(job_id, str) or not ID_RE.fullmatch(job_id):
        raise ConfigError(
            f"{where}: id {job_id!r} is missing or not a valid name; use 1-80 letters, digits, "
            "'.', '_' or '-', starting with a letter or digit (it names the job's output folder)"
        )
    reserved = reserved_names()
    # case-insensitively: on macOS and Windows disks 'Batch-Report.JSON' is the report
    if job_id.casefold() in {n.casefold() for n in reserved}:
        raise ConfigError(
            f"{where}: id {job_id!r} is the name of a file the batch writes in its output folder "
            f"(reserved: {', '.join(sorted(reserved))}); give the job another id"
        )
    if job_id.split(".")[0].upper() in WINDOWS_DEVICES or job_id.endswith("."):
        # a folder named CON, nul.txt or 'job.' cannot be made on Windows (a bureau's share, say): refuse
        # it on every system, so a manifest runs the same everywhere
        raise ConfigError(f"{where}: id {job_id!r} cannot name a folder on Windows (a device name such as CON, "
                          "NUL, COM1 or LPT1, or a trailing '.'); give the job another id")
    where = f"{where} (id {job_id!r})"

    printer = raw.get("printer")
    if not isinstance(printer, str) or not printer.strip():
        raise ConfigError(f"{where}: 'printer' is required: a profile key (see 'saucerfab printers') or a .toml file")
    if _looks_like_path(printer, (".toml",)):
        printer = str(resolve_inside(root, printer, f"{where} printer"))

    cup_mm = raw.get("cup_diameter_mm")
    if isinstance(cup_mm, str):
        try:
            cup_mm = float(cup_mm)
        except ValueError:
            pass
    if isinstance(cup_mm, bool) or not isinstance(cup_mm, (int, float)) or not (0 < cup_mm < 10_000):
        raise ConfigError(f"{where}: 'cup_diameter_mm' is required, a positive number of millimetres; got {cup_mm!r}")

    formats_raw = raw.get("formats", ())
    if isinstance(formats_raw, str):
        formats_raw = [f for f in re.split(r"[\s;,|]+", formats_raw) if f]
    if not isinstance(formats_raw, (list, tuple)) or not all(isinstance(f, str) for f in formats_raw):
        raise ConfigError(f"{where}: 'formats' must be a list of format names, got {formats_raw!r}")
    # a name --formats takes (any case, a leading dot, an alias such as vrml) is the same here
    named = [(f, lookup(f)) for f in formats_raw]
    bad = [f for f, fmt in named if fmt is None or fmt.key not in WRITERS]
    if bad:
        raise ConfigError(f"{where}: unknown format(s) {bad}; known: {list(FORMATS)}")
    formats = tuple(dict.fromkeys(fmt.key for _, fmt in named if fmt is not None))

    has_design = raw.get("design") not in (None, "")
    has_raw = any(raw.get(k) not in (None, "") for k in (*IMAGE_ROLES, "shape", "scene", "cup"))
    design_options = _options(raw.get("design_options"), f"{where} design_options")
    export_options = _options(raw.get("export_options"), f"{where} export_options")
    if has_design and (has_raw or design_options):
        raise ConfigError(
            f"{where}: give either a design folder ('design') or the inputs of a design run "
            "(direct, reflected, shape, scene, cup, design_options), not both"
        )
    _check_export_options(export_options, where)
    common = dict(
        id=job_id,
        printer=printer,
        cup_diameter_mm=float(cup_mm),
        formats=formats,
        export_options=export_options,
        source=where,
    )
    if has_design:
        return JobSpec(design=resolve_inside(root, raw["design"], f"{where} design"), **common)  # type: ignore[arg-type]

    missing = [k for k in ("direct", "reflected") if raw.get(k) in (None, "")]
    if missing:
        raise ConfigError(
            f"{where}: a job needs a design folder ('design') or both images of a design run; "
            f"missing {missing}"
        )
    files: dict[str, Path] = {}
    for k in IMAGE_ROLES:
        if raw.get(k) not in (None, ""):
            files[k] = resolve_inside(root, raw[k], f"{where} {k}")
    shape = raw.get("shape", DesignRequest.default("shape"))
    scene = raw.get("scene", DesignRequest.default("scene"))
    if not isinstance(shape, str) or not shape:
        raise ConfigError(f"{where}: 'shape' must be a built-in shape name or a .png/.npy file, got {shape!r}")
    if not isinstance(scene, str) or not scene:
        raise ConfigError(f"{where}: 'scene' must be a preset name or a .toml file, got {scene!r}")
    shape_name: str | None = shape
    if _looks_like_path(shape, SHAPE_SUFFIXES):
        files["shape"] = resolve_inside(root, shape, f"{where} shape")
        shape_name = None
    else:
        from saucerfab.heightfield import BASE_SHAPES

        if shape.replace("-", "_").lower() not in BASE_SHAPES:
            raise ConfigError(
                f"{where}: unknown base shape {shape!r}; built-in: {sorted(BASE_SHAPES)}, or a .png/.npy file"
            )
    scene_name: str | None = scene
    if scene not in PRESETS:
        if not _looks_like_path(scene, (".toml",)):
            raise ConfigError(f"{where}: scene {scene!r} is neither a preset {sorted(PRESETS)} nor a .toml file")
        files["scene"] = resolve_inside(root, scene, f"{where} scene")
        scene_name = None
    cup = raw.get("cup")
    if cup is not None and (not isinstance(cup, str) or not cup):
        raise ConfigError(f"{where}: 'cup' must be a cup spec like 'circle:0.4', got {cup!r}")
    if cup:
        from saucerfab.scene import parse_cup_spec

        try:
            parse_cup_spec(cup)
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
    allowed = design_option_keys()
    unknown_opts = set(design_options) - allowed
    if unknown_opts:
        raise ConfigError(
            f"{where}: unknown design option(s) {sorted(unknown_opts)}; allowed: {sorted(allowed)}"
        )
    _check_design_options(design_options, files, scene_name, cup or None, where)
    return JobSpec(
        files=files,
        shape=shape_name,
        scene=scene_name,
        cup=cup or None,
        design_options=design_options,
        **common,  # type: ignore[arg-type]
    )


def _type_problem(value: Any, hint: Any) -> str | None:
    """Why ``value`` does not fit the type annotation ``hint``, or None when it does.

    Covers the annotations of :class:`~saucerfab.optimize.request.DesignRequest`'s
    option fields (``int``, ``float``, ``str``, ``bool``, ``X | None``); TOML and
    CSV values are plain, so nothing more is needed. An int is a float
    (``height_scale = 1``); a bool is neither (Python's bool is an int).
    """
    import types
    import typing

    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            return None
        problems = [_type_problem(value, a) for a in args if a is not type(None)]
        return None if any(p is None for p in problems) else " or ".join(p for p in problems if p)
    if hint is bool:
        return None if isinstance(value, bool) else "true or false"
    if hint is int:
        return None if isinstance(value, int) and not isinstance(value, bool) else "a whole number"
    if hint is float:
        return None if isinstance(value, (int, float)) and not isinstance(value, bool) else "a number"
    if hint is str:
        return None if isinstance(value, str) else "a string"
    return None  # an annotation this check does not know: the request's own checks judge the value


@functools.lru_cache(maxsize=1)
def _request_hints() -> dict[str, Any]:
    """:class:`DesignRequest`'s field annotations, evaluated once (get_type_hints is slow)."""
    import typing

    return typing.get_type_hints(DesignRequest)


def _check_design_options(
    options: dict[str, Any], files: dict[str, Path], scene: str | None, cup: str | None, where: str
) -> None:
    """Refuse, at load, every design option value ``saucerfab design`` would refuse before its work.

    The rules are the CLI's own, not copies: the option types are the
    :class:`DesignRequest` field annotations (argparse's ``type=`` on the
    command line), the value checks are ``DesignRequest``'s (with
    :func:`~saucerfab.optimize.stages.check_weights`: a weight no stage uses), and the
    resolution and image-size ranges are those of the scene the run builds
    (:func:`~saucerfab.optimize.prepare.build_scene`, as the design's
    ``prepare`` does). A job with a scene *file* has its overrides checked on
    the paper preset's scene (the ranges do not depend on the scene) and
    its cup with the scene file when the job runs: the file is the job's
    input, read when the job runs, not when the manifest loads.
    """
    from saucerfab.errors import SaucerfabError
    from saucerfab.heightfield import check_height_scale
    hints = _request_hints()
    for name, value in sorted(options.items()):
        want = _type_problem(value, hints.get(name))
        if want is not None:
            raise ConfigError(f"{where} design_options: {name} must be {want}, got {value!r}")
    try:
        request = DesignRequest(direct=files["direct"], reflected=files["reflected"], **options)
        check_height_scale(request.height_scale)
    except SaucerfabError as exc:
        raise ConfigError(f"{where} design_options: {exc}") from None
    except TypeError as exc:
        raise ConfigError(f"{where} design_options: {exc}") from None
    scene, cup = (scene, cup) if scene is not None else ("paper", None)
    try:
        key = json.dumps(options, sort_keys=True)
    except (TypeError, ValueError):  # a value JSON cannot hold (a TOML date): check it uncached
        problem = _scene_problem(scene, cup, options)
    else:
        problem = _scene_problem_cached(scene, cup, key)
    if problem is not None:
        raise ConfigError(f"{where} design_options: {problem}")


def _scene_problem(scene: str, cup: str | None, options: dict[str, Any]) -> str | None:
    """Why the design run's scene (preset ``scene``, ``cup`` override) cannot be built
    with these design options, in the design's own words, or None when it can."""
    from saucerfab.errors import SaucerfabError
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


def _check_export_options(options: dict[str, Any], where: str) -> None:
    from saucerfab.fabricate.options import FabOptions

    allowed = export_option_keys()
    unknown = set(options) - allowed
    if unknown:
        raise ConfigError(f"{where}: unknown export option(s) {sorted(unknown)}; allowed: {sorted(allowed)}")
    try:
        FabOptions(**options)
    except (ConfigError, TypeError) as exc:
        raise ConfigError(f"{where} export_options: {exc}") from None


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


def _read_text(path: Path) -> str:
    if not path.is_file():
        raise ConfigError(f"manifest {str(path)!r} not found")
    if path.stat().st_size > MAX_MANIFEST_BYTES:
        raise ConfigError(f"manifest {str(path)!r} is over {MAX_MANIFEST_BYTES >> 20} MB; split it")
    try:
        return path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read manifest {str(path)!r}: {exc}") from None


def nesting_depth(value: Any) -> int:
    """How deeply arrays and tables nest in ``value`` (a scalar: 0), without recursion.

    Counting stops past :data:`MAX_NESTING`, so the answer is at most one more.
    """
    deepest = 0
    stack: list[tuple[Any, int]] = [(value, 0)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, dict):
            v = list(v.values())
        if isinstance(v, (list, tuple)):
            depth += 1
            deepest = max(deepest, depth)
            if depth <= MAX_NESTING:  # deeper is refused anyway: stop counting
                stack.extend((x, depth) for x in v)
    return deepest


def _toml_loads(text: str, what: str) -> dict[str, Any]:
    """``tomllib.loads`` with a syntax error, or nesting too deep, as a :class:`ConfigError`.

    tomllib parses arrays and inline tables recursively: a file nesting a few
    thousand of them exhausts the stack (RecursionError), which is the file's
    fault, not a crash.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{what} is not valid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(
            f"{what} nests arrays or tables too deeply to be read; "
            f"a manifest needs at most {MAX_NESTING} levels: remove the nesting"
        ) from None
    if nesting_depth(data) > MAX_NESTING:
        raise ConfigError(
            f"{what} nests arrays or tables over {MAX_NESTING} levels deep; a manifest needs "
            "at most a few (a job's option table holds lists of numbers at most): remove the nesting"
        )
    return data


def _toml_rows(path: Path, text: str) -> tuple[dict[str, Any], list[tuple[str, dict[str, Any]]]]:
    data = _toml_loads(text, f"manifest {str(path)!r}")
    unknown = set(data) - {"defaults", "job", "batch"}
    if unknown:
        raise ConfigError(
            f"manifest {str(path)!r}: unknown top-level key(s) {sorted(unknown)}; "
            "use [defaults], [[job]] (and optionally [batch] version = 1)"
        )
    batch = data.get("batch", {})
    if not isinstance(batch, dict) or set(batch) - {"version"} or batch.get("version", 1) != 1:
        raise ConfigError(f"manifest {str(path)!r}: [batch] may only hold version = 1, got {batch!r}")
    defaults = data.get("defaults", {})
    if not isinstance(defaults, dict):
        raise ConfigError(f"manifest {str(path)!r}: [defaults] must be a table")
    if "id" in defaults:
        raise ConfigError(f"manifest {str(path)!r}: [defaults] cannot set 'id' (each job has its own)")
    jobs = data.get("job", [])
    if not isinstance(jobs, list) or not all(isinstance(j, dict) for j in jobs):
        raise ConfigError(f"manifest {str(path)!r}: jobs are written as [[job]] tables")
    return defaults, [(f"{path.name} job #{i + 1}", j) for i, j in enumerate(jobs)]


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
        except RecursionError:  # see _toml_loads
            raise ConfigError(f"{where}: the value of {k!r} nests arrays or tables too deeply to be read") from None
        if nesting_depth(out[k]) > MAX_NESTING:
            raise ConfigError(
                f"{where}: the value of {k!r} nests arrays or tables over {MAX_NESTING} levels deep; remove the nesting"
            )
    return out


def _csv_rows(path: Path, text: str) -> list[tuple[str, dict[str, Any]]]:
    lines = [ln for ln in text.splitlines() if not ln.lstrip().startswith("#")]
    reader = csv.DictReader(io.StringIO("\n".join(lines)), skipinitialspace=True)
    if not reader.fieldnames:
        raise ConfigError(f"manifest {str(path)!r} is empty; the first row names the columns (id,design,...)")
    header = [h.strip() for h in reader.fieldnames]
    unknown = set(header) - JOB_KEYS
    if unknown:
        raise ConfigError(
            f"manifest {str(path)!r}: unknown column(s) {sorted(unknown)}; allowed: {sorted(JOB_KEYS)}"
        )
    rows = []
    for n, row in enumerate(reader, start=1):
        where = f"{path.name} row {n}"
        if None in row:
            raise ConfigError(f"{where}: more cells than columns")
        job: dict[str, Any] = {}
        for k, v in row.items():
            v = (v or "").strip()
            if not v:
                continue
            k = k.strip()
            job[k] = parse_options_cell(v, f"{where} {k}") if k in ("design_options", "export_options") else v
        if job:
            rows.append((where, job))
    return rows


def load_manifest(path: str | os.PathLike[str]) -> Manifest:
    """Read, validate and resolve a manifest (``.toml`` or ``.csv``).

    Raises:
        ConfigError: listing every structural problem found (bad syntax, unknown
            keys, duplicate ids, paths leaving the manifest's folder...).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".csv"):
        raise ConfigError(f"manifest {str(path)!r}: use a .toml or .csv file")
    text = _read_text(path)
    root = path.resolve().parent
    if suffix == ".toml":
        defaults, rows = _toml_rows(path, text)
    else:
        defaults, rows = {}, _csv_rows(path, text)
    if not rows:
        raise ConfigError(f"manifest {str(path)!r} lists no jobs")
    if len(rows) > MAX_JOBS:
        raise ConfigError(f"manifest {str(path)!r} lists {len(rows)} jobs; at most {MAX_JOBS}, split it")
    problems: list[str] = []
    jobs: list[JobSpec] = []
    seen: dict[str, str] = {}
    for where, raw in rows:
        try:
            job = _build_job(_merge(defaults, raw), root, where)
        except ConfigError as exc:
            problems.append(str(exc))
            continue
        folded = job.id.lower()  # output folders must not collide on case-insensitive disks
        if folded in seen:
            problems.append(f"{where}: id {job.id!r} is used twice (also {seen[folded]}); ids name output folders")
            continue
        seen[folded] = where
        jobs.append(job)
    if problems:
        shown = problems[:20]
        more = f"\n  ... and {len(problems) - 20} more" if len(problems) > 20 else ""
        raise ConfigError(
            f"manifest {str(path)!r} has {len(problems)} problem(s); nothing was run:\n  "
            + "\n  ".join(shown)
            + more
        )
    return Manifest(path=path.resolve(), root=root, jobs=tuple(jobs))
