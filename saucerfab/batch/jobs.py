"""One batch job: its inputs and key, the work (design, export, check), its output folder.

The work is split so that it can run anywhere:

* :func:`load_payload` (driver) reads the job's input files into memory,
  resolves the printer profile and computes the job key;
* :func:`execute` (a worker: this process, a pool process or a Dask worker)
  writes those bytes into a scratch folder, runs design (raw-input jobs),
  export and check there, and returns every output file as bytes in a
  :class:`JobResult`; it reads no path of the driver and writes nothing the
  driver sees, so workers need no shared file system and a killed worker
  leaves nothing behind in the output;
* :func:`commit` (driver) writes the job's output folder atomically, the
  completion marker ``job.json`` last, and :func:`completed` tells whether an
  existing folder is complete and made from the same inputs.

The job key is the sha256 of the canonical JSON of the saucerfab version, the
sha256 of every input file (by its role, not its path: moving the manifest's
folder keeps the keys), the printer profile's values and the job's parameters.

:func:`run_job` does all of it for one job in this process.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import socket
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from saucerfab import __version__
from saucerfab.batch.manifest import JobSpec
from saucerfab.errors import InputFileError, Interrupted, SaucerfabError
from saucerfab.files.fileio import atomic_dir, sha256_file
from saucerfab.optimize.request import IMAGE_ROLES

MARKER = "job.json"
MARKER_SCHEMA = "saucerfab.batch-job/1"
KEY_SCHEMA = 1
#: most bytes of input one job may carry (images, shape, scene, design folder)
MAX_JOB_INPUT_BYTES = 1 << 30
#: most files in one design folder
MAX_DESIGN_FILES = 10_000
STAGES = ("design", "export", "check")
VERDICT_RANK = {"printable": 0, "not printable": 1, "unreadable": 2}

#: an event sink a worker reports stage starts to: (job id, stage) -> None
EventSink = Callable[[str, str], None]


@dataclass
class Payload:
    """Everything a worker needs to run one job; travels to the worker by pickle.

    ``files`` maps a path relative to the job's input folder (``design/heights.npy``,
    ``direct/rose.png``, ``shape/dome.npy``, ``scene/cup.toml``) to its bytes; ``sources``
    maps those names (and ``design``) to the paths the manifest gave, so that
    messages name the user's files, not the worker's scratch copies.
    """

    job_id: str
    key: str
    kind: str
    files: dict[str, bytes]
    printer: Any  # PrinterProfile (kept Any so this module imports without the profiles)
    cup_diameter_mm: float | None  # None: the scene's (a design folder's own)
    formats: tuple[str, ...]
    request: dict[str, Any] = field(default_factory=dict)
    export_options: dict[str, Any] = field(default_factory=dict)
    scratch_root: str | None = None
    threads: int = 1
    event_topic: str | None = None
    sources: dict[str, str] = field(default_factory=dict)


@dataclass
class JobResult:
    """What a worker sends back: the outcome and every output file's bytes.

    Attributes:
        status: ``"ok"`` or ``"failed"``.
        stage: the stage that failed (``inputs``, ``design``, ``export``, ``check``), else None.
        reason: why it failed, in words, else None.
        verdict: the worst check verdict over the exported files (``printable``,
            ``not printable``, ``unreadable``), if the check ran.
        complete: the outputs are complete (every stage ran); true also for a
            job whose check verdict failed, which is kept and not run again.
        files: output files by path relative to the job's folder.
        checks: per checked file, the check report's verdict, exit code and finding counts.
        times: seconds per stage and ``total``.
        trace: traceback text for an unexpected (non-saucerfab) error.
        worker: host and process that ran the job.
    """

    job_id: str
    key: str
    status: str
    stage: str | None = None
    reason: str | None = None
    verdict: str | None = None
    complete: bool = False
    files: dict[str, bytes] = field(default_factory=dict)
    checks: dict[str, Any] = field(default_factory=dict)
    times: dict[str, float] = field(default_factory=dict)
    trace: str | None = None
    worker: str = ""


class JobInputError(InputFileError):
    """A job's input files cannot be read (missing, too large, not a folder)."""


# --------------------------------------------------------------------------- driver side


def _read_limited(path: Path, budget: list[int], what: str) -> bytes:
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise JobInputError(f"{what} {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    if not path.is_file():
        raise JobInputError(f"{what} {str(path)!r} is not a file")
    budget[0] -= size
    if budget[0] < 0:
        raise JobInputError(
            f"{what} {str(path)!r}: the job's inputs exceed {MAX_JOB_INPUT_BYTES >> 20} MB; "
            "that is more than any design needs"
        )
    try:
        return path.read_bytes()
    except OSError as exc:
        raise JobInputError(f"{what} {str(path)!r} cannot be read: {exc.strerror or exc}") from None


def read_inputs(job: JobSpec, root: Path) -> dict[str, bytes]:
    """The job's input files as bytes, by path relative to the job's input folder.

    Design folders are read whole (every file under them); a file or link that
    resolves outside ``root`` (the manifest's folder) is refused.

    Raises:
        JobInputError: a file is missing, unreadable, outside ``root`` or too large.
    """
    budget = [MAX_JOB_INPUT_BYTES]
    root_real = root.resolve()
    files: dict[str, bytes] = {}
    if job.design is not None:
        folder = job.design
        if not folder.is_dir():
            raise JobInputError(
                f"design folder {str(folder)!r} does not exist or is not a folder; "
                "make one with 'saucerfab design'"
            )
        count = 0
        for dirpath, dirnames, filenames in os.walk(folder):
            dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
            for name in sorted(filenames):
                if name.startswith("."):
                    continue  # editor/OS droppings and unfinished temporaries
                p = Path(dirpath) / name
                real = p.resolve()
                if not real.is_relative_to(root_real):
                    raise JobInputError(
                        f"{str(p)!r} links to {str(real)!r}, outside the manifest's folder; copy it in"
                    )
                count += 1
                if count > MAX_DESIGN_FILES:
                    raise JobInputError(f"design folder {str(folder)!r} holds over {MAX_DESIGN_FILES} files")
                rel = p.relative_to(folder).as_posix()
                files[f"design/{rel}"] = _read_limited(p, budget, "design file")
        if "design/design.json" not in files:
            raise JobInputError(
                f"{str(folder)!r} is not a design folder (no design.json); make one with 'saucerfab design'"
            )
        return files
    for role, path in sorted(job.files.items()):
        # role/name: the design records input file names, so keep the user's
        files[f"{role}/{path.name}"] = _read_limited(path, budget, f"{role} file")
    return files


def _profile_data(profile: Any) -> dict[str, Any]:
    d = asdict(profile)
    return json.loads(json.dumps(d))  # tuples -> lists, canonical


def resolve_formats(job: JobSpec, profile: Any) -> tuple[str, ...]:
    """The job's formats, or the printer's preferred format when none are given."""
    return job.formats or (profile.preferred_format,)


def job_key(job: JobSpec, files: dict[str, bytes], profile: Any) -> str:
    """The job key: sha256 over version, input hashes, printer profile and parameters."""
    material = {
        "key_schema": KEY_SCHEMA,
        "saucerfab": __version__,
        "kind": job.kind,
        "inputs": {rel: hashlib.sha256(data).hexdigest() for rel, data in sorted(files.items())},
        "printer": _profile_data(profile),
        # None (the scene's) is the value of input files hashed above, or of the version's preset
        "cup_diameter_mm": None if job.cup_diameter_mm is None else float(job.cup_diameter_mm),
        "formats": list(resolve_formats(job, profile)),
        "shape": job.shape,
        "scene": job.scene,
        "cup": job.cup,
        "design_options": job.design_options,
        "export_options": job.export_options,
    }
    text = json.dumps(material, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def load_payload(
    job: JobSpec,
    root: Path,
    *,
    scratch_root: str | os.PathLike[str] | None = None,
    threads: int = 1,
    event_topic: str | None = None,
) -> Payload:
    """Read a job's inputs and printer into a :class:`Payload` with its key.

    Raises:
        SaucerfabError: an input is missing or unreadable, or the printer is unknown.
    """
    from saucerfab.model.profiles import load_profile

    printer = job.printer
    try:
        files = read_inputs(job, root)
        if printer is None:  # a design folder's job without one: the printer the design was made for
            printer = design_printer(_json_or_none(files.get("design/design.json", b"")))
        try:
            profile = load_profile(printer)
        except SaucerfabError as exc:
            if job.printer is not None:
                raise
            raise type(exc)(f"{exc} (the printer the design folder's design.json names; "
                            "give the job a 'printer')") from None
    except SaucerfabError as exc:  # name files as the manifest does, relative to its folder
        exc.args = (str(exc).replace(str(root.resolve()) + os.sep, ""),)
        raise
    key = job_key(job, files, profile)
    request: dict[str, Any] = {}
    if job.design is not None:
        sources = {"design": _shown(job.design, root)}
    else:
        sources = {f"{role}/{path.name}": _shown(path, root) for role, path in job.files.items()}
    if job.kind == "raw":
        by_role = {rel.split("/", 1)[0]: rel for rel in files}
        request = dict(job.design_options)
        for role in IMAGE_ROLES:
            if role in by_role:
                request[role] = by_role[role]
        request["shape"] = by_role.get("shape", job.shape)
        request["scene"] = by_role.get("scene", job.scene)
        if job.cup:
            request["cup"] = job.cup
        # the design is made for the printer and cup the job exports for (None: the scene's)
        request["printer"] = printer
        request["cup_diameter_mm"] = job.cup_diameter_mm
    return Payload(
        job_id=job.id,
        key=key,
        kind=job.kind,
        files=files,
        printer=profile,
        cup_diameter_mm=job.cup_diameter_mm,
        formats=resolve_formats(job, profile),
        request=request,
        export_options=dict(job.export_options),
        scratch_root=os.fspath(scratch_root) if scratch_root is not None else None,
        threads=threads,
        event_topic=event_topic,
        sources=sources,
    )


def design_printer(design_json: Any) -> str:
    """The printer (a profile key, never a path) a design was made for, from its design.json: ``parameters.printer``
    (as ``saucerfab design --printer`` was given), else ``parameters.print_target.printer``, else
    :data:`~saucerfab.model.profiles.DEFAULT_PRINTER` (a synthetic design, one older than the print
    target, or an unreadable design.json: the export then says what is wrong with the folder).

    The printer a job with a design folder and no ``printer`` exports for: the rule of
    ``saucerfab export`` without ``--printer`` (``saucerfab.fabricate.pipeline.export_printer``),
    read from design.json alone, since the driver does not load a job's design.
    """
    from saucerfab.model.design import Intent
    from saucerfab.model.profiles import DEFAULT_PRINTER

    made = Intent.of(design_json.get("parameters") if isinstance(design_json, dict) else None).printer
    return DEFAULT_PRINTER if made is None else made


def _json_or_none(data: bytes) -> Any:
    """``data`` parsed as JSON, or None when it is not JSON."""
    try:
        return json.loads(data)
    except (ValueError, RecursionError):
        return None


def _shown(path: Path, root: Path) -> str:
    try:
        return path.relative_to(root.resolve()).as_posix()
    except ValueError:
        return str(path)


# --------------------------------------------------------------------------- worker side

#: set in pool worker processes by the executor: where stage events go
_EVENT_SINK: EventSink | None = None


def set_event_sink(sink: EventSink | None) -> None:
    global _EVENT_SINK
    _EVENT_SINK = sink


def _emit(payload: Payload, stage: str) -> None:
    try:
        if _EVENT_SINK is not None:
            _EVENT_SINK(payload.job_id, stage)
        elif payload.event_topic:
            from distributed import get_worker

            get_worker().log_event(payload.event_topic, {"job": payload.job_id, "stage": stage})
    except Exception:  # noqa: BLE001 - progress display must never fail a job
        pass


#: one design at a time per process: torch's thread count is process-wide (a
#: threaded Dask worker runs several jobs in one process; exports and checks
#: still run side by side)
_DESIGN_LOCK = threading.Lock()


@contextlib.contextmanager
def _torch_threads(n: int) -> Iterator[None]:
    """``n`` torch threads for one design: workers run side by side without
    oversubscribing the cores, and a design does not depend on the machine's
    core count. The caller's setting is restored afterwards."""
    import torch

    before = torch.get_num_threads()
    if before != n:
        torch.set_num_threads(n)
    try:
        yield
    finally:
        if torch.get_num_threads() != before:
            torch.set_num_threads(before)


def _collect(folder: Path, prefix: str) -> dict[str, bytes]:
    out: dict[str, bytes] = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file() and not p.name.startswith("."):
            out[f"{prefix}/{p.relative_to(folder).as_posix()}"] = p.read_bytes()
    return out


def _run_stages(payload: Payload, work: Path, times: dict[str, float], stage: list[str]) -> JobResult:
    from saucerfab.fabricate.options import FabOptions
    from saucerfab.workflow import make_print

    inp, out = work / "in", work / "out"
    for rel, data in payload.files.items():
        p = inp / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data)
    out.mkdir()
    files: dict[str, bytes] = {}

    if payload.kind == "raw":
        stage[0] = "design"
        _emit(payload, "design")
        from saucerfab.optimize.request import DesignRequest
        from saucerfab.workflow import run_design

        kw = dict(payload.request)
        for role in IMAGE_ROLES:
            if role in kw:
                kw[role] = inp / kw[role]
        for role in ("shape", "scene"):
            if kw.get(role) in payload.files:  # a file the job carries, not a built-in name
                # a Path, so that the design folder records the file's name, not the scratch path
                kw[role] = inp / kw[role]

        def progress(name: str, it: int, max_it: int, parts: dict[str, float], elapsed: float) -> None:
            _emit(payload, f"design {name} {it}/{max_it}")

        # no wall-clock times in the design folder: a job's outputs are byte-identical run to run
        kw.setdefault("record_times", False)
        request = DesignRequest(**kw)
        with _DESIGN_LOCK, _torch_threads(payload.threads):
            t = time.perf_counter()
            design_dir = run_design(request, out / "design", progress=progress).folder
            times["design"] = time.perf_counter() - t
        files.update(_collect(design_dir, "design"))
    else:
        design_dir = inp / "design"

    export_dir = out / "export"
    started = [time.perf_counter()]

    def on_stage(name: str) -> None:
        # the report is timed with the verify (the batch report's columns: export, check, verify)
        if name == "report":
            return
        now = time.perf_counter()
        if stage[0] in ("export", "check", "verify"):
            times[stage[0]] = now - started[0]
        started[0] = now
        stage[0] = name
        _emit(payload, name)

    def export_progress(step: str, fraction: float) -> None:
        _emit(payload, f"export {step} {fraction:.0%}")

    # the quick ray-traced verify and the print's report.html without times, and each file's check in the
    # job's check/ folder rather than a check.json in the print: byte-identical reruns
    done = make_print(design_dir, export_dir, printer=payload.printer, cup_diameter_mm=payload.cup_diameter_mm,
                      formats=list(payload.formats), options=FabOptions(**payload.export_options),
                      progress=export_progress, record_times=False, write_check_json=False, scratch=work,
                      on_stage=on_stage)
    times[stage[0]] = time.perf_counter() - started[0]
    checks: dict[str, Any] = {}
    reasons: list[str] = []
    for checked in done.checks:
        rel = f"export/{checked.name}"  # a zipped OBJ's entry: export/<zip>/<obj>
        report = checked.report
        if report is None:
            raise SaucerfabError(f"{rel} was not checked: saucerfab.check cannot be imported; reinstall saucerfab")
        d = report.to_dict()
        d["path"] = rel  # the path inside the job's folder, not the worker's scratch
        d.pop("elapsed_s", None)  # times go to the batch report; job files stay byte-identical
        text = json.dumps(d, indent=2, sort_keys=True)
        for prefix in {str(export_dir) + os.sep, str(export_dir.resolve()) + os.sep}:
            text = text.replace(json.dumps(prefix)[1:-1], "export/")
        files[f"check/{rel[len('export/'):]}.json"] = (text + "\n").encode()
        checks[rel] = {
            "verdict": report.verdict,
            "exit_code": int(report.exit_code),
            "findings": _finding_counts(report),
        }
        if report.exit_code != 0:
            reasons.append(f"{rel}: {report.reason()}")
    files.update(_collect(export_dir, "export"))
    verdict = max((c["verdict"] for c in checks.values()), key=lambda v: VERDICT_RANK.get(v, 3))
    return JobResult(
        job_id=payload.job_id,
        key=payload.key,
        status="failed" if reasons else "ok",
        stage="check" if reasons else None,
        reason="; ".join(reasons) if reasons else None,
        verdict=verdict,
        complete=True,
        files=files,
        checks=checks,
    )


def _finding_counts(report: Any) -> dict[str, int]:
    counts: dict[str, int] = {}
    for f in getattr(report, "findings", []) or []:
        sev = getattr(f, "severity", None)
        sev = getattr(sev, "value", sev)
        counts[str(sev).lower()] = counts.get(str(sev).lower(), 0) + 1
    return dict(sorted(counts.items()))


def _user_paths(text: str, payload: Payload, work: Path) -> str:
    """``text`` with the worker's scratch paths replaced by the manifest's paths."""
    pairs = [(str(work / "in" / rel), shown) for rel, shown in payload.sources.items()]
    pairs += [(str(work / "out"), "<output>"), (str(work / "in"), "<inputs>"), (str(work), "<scratch>")]
    for scratch, shown in sorted(pairs, key=lambda p: -len(p[0])):
        text = text.replace(scratch, shown)
    return text


def execute(payload: Payload) -> JobResult:
    """Run one job's stages in a scratch folder; return its outcome and output bytes.

    Never raises for a failing job (the failure is the result); only
    ``KeyboardInterrupt``, :class:`~saucerfab.errors.Interrupted` and
    ``SystemExit`` pass through.
    """
    t0 = time.perf_counter()
    times: dict[str, float] = {}
    stage = ["inputs"]
    root = payload.scratch_root
    if root is not None:
        Path(root).mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f"{payload.job_id}.", dir=root))
    try:
        res = _run_stages(payload, work, times, stage)
    except Interrupted:
        raise  # Ctrl-C inside a stage (the design turns it into Interrupted) stops the batch
    except SaucerfabError as exc:
        res = JobResult(payload.job_id, payload.key, "failed", stage=stage[0], reason=str(exc))
    except MemoryError:
        res = JobResult(payload.job_id, payload.key, "failed", stage=stage[0], reason="out of memory")
    except Exception as exc:  # noqa: BLE001 - a bug in one job must not stop the batch
        res = JobResult(
            payload.job_id,
            payload.key,
            "failed",
            stage=stage[0],
            reason=f"internal error: {type(exc).__name__}: {exc}",
            trace=traceback.format_exc(),
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    if res.reason:
        res.reason = _user_paths(res.reason, payload, work)
    if res.trace:
        res.trace = _user_paths(res.trace, payload, work)
    times["total"] = time.perf_counter() - t0
    res.times = {k: round(v, 4) for k, v in times.items()}
    res.worker = f"{socket.gethostname()}:{os.getpid()}"
    return res


# --------------------------------------------------------------------------- output folder


def marker_dict(result: JobResult) -> dict[str, Any]:
    """The completion marker ``job.json``: deterministic (no times, no hosts)."""
    return {
        "schema": MARKER_SCHEMA,
        "id": result.job_id,
        "key": result.key,
        "saucerfab_version": __version__,
        "complete": result.complete,
        "status": result.status,
        "stage": result.stage,
        "reason": result.reason,
        "verdict": result.verdict,
        "checks": result.checks,
        "files": {rel: hashlib.sha256(data).hexdigest() for rel, data in sorted(result.files.items())},
        **({"traceback": result.trace} if result.trace else {}),
    }


def commit(result: JobResult, out_root: Path) -> Path:
    """Write the job's output folder ``out_root/<id>`` atomically, marker last.

    A folder already there (an earlier run with other inputs, or a failed run)
    is replaced only once the new one is complete.
    """
    dest = out_root / result.job_id
    with atomic_dir(dest) as tmp:
        for rel, data in sorted(result.files.items()):
            p = tmp / rel
            p.parent.mkdir(parents=True, exist_ok=True)
            with open(p, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
        text = json.dumps(marker_dict(result), indent=2, sort_keys=True) + "\n"
        with open(tmp / MARKER, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
    return dest


def read_marker(folder: Path) -> dict[str, Any] | None:
    """The folder's ``job.json`` as a dict, or None if absent or unreadable."""
    try:
        d = json.loads((folder / MARKER).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return d if isinstance(d, dict) and d.get("schema") == MARKER_SCHEMA else None


def completed(out_root: Path, job_id: str, key: str) -> dict[str, Any] | None:
    """The marker of ``out_root/<job_id>`` if that job is complete for ``key``, else None.

    Complete means: the marker says so, its key is ``key``, and every file it
    lists is there with the sha256 it lists.
    """
    folder = out_root / job_id
    marker = read_marker(folder)
    if not marker or marker.get("key") != key or marker.get("complete") is not True:
        return None
    listed = marker.get("files")
    if not isinstance(listed, dict):
        return None
    for rel, digest in listed.items():
        p = folder / rel
        if not p.is_file() or sha256_file(p) != digest:
            return None
    return marker


def result_from_marker(marker: dict[str, Any]) -> JobResult:
    """A :class:`JobResult` (without file bytes) for a job found complete on disk."""
    return JobResult(
        job_id=str(marker["id"]),
        key=str(marker["key"]),
        status=str(marker.get("status", "ok")),
        stage=marker.get("stage"),
        reason=marker.get("reason"),
        verdict=marker.get("verdict"),
        complete=True,
        checks=dict(marker.get("checks") or {}),
    )


def failed_result(job: JobSpec, stage: str, reason: str, key: str = "") -> JobResult:
    """A failure recorded without running the job (unreadable inputs, a worker that died)."""
    return JobResult(job.id, key, "failed", stage=stage, reason=reason)


def run_job(
    job: JobSpec,
    root: Path,
    out_root: Path,
    *,
    force: bool = False,
) -> tuple[JobResult, bool]:
    """Run one job in this process end to end: inputs, design, export, check, commit.

    Returns ``(result, reused)``: ``reused`` is true when the job was complete
    on disk for the same key and nothing ran.
    """
    try:
        payload = load_payload(job, root)
    except SaucerfabError as exc:
        return failed_result(job, "inputs", str(exc)), False
    if not force:
        marker = completed(out_root, job.id, payload.key)
        if marker is not None:
            return result_from_marker(marker), True
    result = execute(payload)
    commit(result, out_root)
    return result, False
