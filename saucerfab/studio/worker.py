"""What runs in a studio worker process: one design job or one export job.

:func:`main` is the process's target (``multiprocessing`` spawn context,
started by :mod:`saucerfab.studio.jobs`). It reports only through files in the
run folder, written atomically: ``progress.json`` while a design runs (at
most :data:`WRITES_PER_S` times a second), the looks in ``looks/``, and the
run's record (``run.json``, under the run's lock) when the job ends. Its
stdout and stderr go to ``worker.log`` in the run folder, where a traceback
of an unexpected fault stays (the client sees a one-line message naming it).

Stopping: SIGINT (the studio's cancel, or the server shutting down) is
Python's KeyboardInterrupt; ``run_design`` saves its checkpoint
(``.design.checkpoint/``) and raises :class:`~saucerfab.errors.Interrupted`.
The record then says ``cancelled`` when the studio asked for it
(``cancelling``) and ``interrupted`` otherwise. A worker whose server died
stops the same way: it watches its parent process.
"""

from __future__ import annotations

import os
import shutil
import signal
import sys
import threading
import time
import traceback
import zipfile
from pathlib import Path
from typing import Any

from saucerfab.errors import Interrupted, SaucerfabError
from saucerfab.files.fileio import write_bytes_atomic
from saucerfab.studio.workspace import Workspace, now_iso, owner_of, write_json

#: the most progress.json writes a second (the page polls it through the event stream)
WRITES_PER_S = 4.0
#: how often the parent-watching thread looks, seconds
PARENT_POLL_S = 0.5


class _ParentWatch:
    """Stops the worker (as Ctrl-C does: the checkpoint is saved) once the server process is gone.

    The progress callback checks :meth:`gone` between iterations; a thread
    covers the phases without callbacks (reading inputs, verify) by sending
    SIGINT to this process. Either fires once.
    """

    def __init__(self) -> None:
        self.parent = os.getppid()
        self.fired = False
        self._lock = threading.Lock()
        threading.Thread(target=self._watch, name="parent-watch", daemon=True).start()

    def _dead(self) -> bool:
        return os.getppid() != self.parent  # re-parented: the server died

    def _fire(self) -> bool:
        with self._lock:
            first, self.fired = not self.fired, True
            return first

    def gone(self) -> bool:
        """True once, the first time the parent is found gone (the caller then raises KeyboardInterrupt)."""
        return self._dead() and self._fire()

    def _watch(self) -> None:
        while True:
            time.sleep(PARENT_POLL_S)
            if self._dead():
                time.sleep(2 * PARENT_POLL_S)  # let the progress callback stop it between iterations
                if self._fire():
                    print("studio worker: the server is gone; stopping (the checkpoint is saved)", file=sys.stderr)
                    os.kill(os.getpid(), signal.SIGINT)
                return


def _log_to(path: Path) -> None:
    """Point this process's stdout and stderr (file descriptors 1 and 2) at ``path`` (appended)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o666)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    sys.stdout = open(1, "w", buffering=1, closefd=False)  # noqa: SIM115 (lives as long as the process)
    sys.stderr = open(2, "w", buffering=1, closefd=False)  # noqa: SIM115


#: set once the studio has asked this worker to stop (SIGINT)
_STOP_ASKED = False


def _on_sigint(signum: int, frame: Any) -> None:
    """Python's own Ctrl-C behaviour (KeyboardInterrupt), remembering that a stop was asked.

    A library call the interrupt lands in may turn it into an error of its
    own (a native extension, a compile); once a stop was asked, such an
    error is the stop, not a fault of the design, and the run is recorded
    as interrupted (its checkpoint keeps the stages that had finished).
    """
    global _STOP_ASKED
    _STOP_ASKED = True
    raise KeyboardInterrupt


def main(root: str, kind: str, run_id: str, printer: str | None = None) -> None:
    """The worker process: run job ``kind`` ("design", "export" or "lit") of run ``run_id`` in workspace ``root``."""
    # Its own process group: a Ctrl-C at the server's terminal reaches the server only, which then
    # sends each worker exactly one SIGINT (a second one could cut the checkpoint's save short).
    if hasattr(os, "setpgrp"):
        os.setpgrp()
    # SIGINT is how the studio cancels (run_design saves its checkpoint on KeyboardInterrupt). A server
    # started in the background by a non-interactive shell (`saucerfab studio &`, nohup, some service
    # managers) has SIGINT ignored, and a spawned worker inherits that: it would never stop. Take it back.
    signal.signal(signal.SIGINT, _on_sigint)
    ws = Workspace(root, create=False)
    folder = ws.runs / run_id
    _log_to(folder / "worker.log")
    print(f"--- {now_iso()} studio worker pid {os.getpid()}: {kind} {run_id} {printer or ''}", file=sys.stderr)
    watch = _ParentWatch()
    if kind == "design":
        _design_job(ws, run_id, watch)
    elif kind == "lit":  # an export seen under the room light
        from saucerfab.studio.lit import lit_job

        lit_job(ws, run_id, str(printer))
    else:
        _export_job(ws, run_id, str(printer))
    sys.stderr.flush()


def _end(ws: Workspace, run_id: str, status: str, error: str | None = None, notes: list[str] | None = None) -> None:
    """Record how the design job ended; a cancel asked for turns an interruption into ``cancelled``."""

    def change(rec: dict[str, Any]) -> None:
        s, why = status, error
        if s == "interrupted" and rec.get("status") == "cancelling":
            s = "cancelled"
        if s == "cancelled":
            why = "cancelled; resume continues after the last stage that had finished"
        elif s == "interrupted":
            why = ("the studio stopped while this design was running; resume continues after the last stage "
                   "that had finished")
        rec.update(status=s, finished=now_iso(), error=why)
        if notes is not None:
            rec["notes"] = notes

    ws.update_run(run_id, change)


def _plans(request: Any) -> list[list[str]]:
    """The stage names the request can run: with the black-white enhancement, then with the pictures as they are.

    Which one runs is known once run_design has read the pictures (with
    ``--enhancement auto``); under the default method the two differ in
    length as well as in names (the small-sigma stage runs only without
    the enhancement: :func:`saucerfab.optimize.stages.skips_small_sigma`).
    """
    from saucerfab.optimize.stages import stages_for, without_enhancement

    return [[s.name for s in stages_for(request.ablation, request.method, True)],
            [s.name for s in without_enhancement(stages_for(request.ablation, request.method, False))]]


class _Reporter:
    """progress.json and looks/ of a running design (the ``progress`` and ``look`` callbacks of run_design)."""

    def __init__(self, folder: Path, request: Any, watch: _ParentWatch, scrub: Any = str) -> None:
        self.folder = folder
        self.scrub = scrub  # takes the workspace's path out of a message
        self.watch = watch
        self.plans = _plans(request)
        # until a stage's name tells which plan runs, the one its enhancement option implies
        self.plan = self.plans[1 if request.enhancement == "none" else 0]
        self.t0 = time.perf_counter()
        self.last = 0.0
        self.last_stage: str | None = None
        self.doc: dict[str, Any] = {"stage": None, "stage_index": 0, "stages": len(self.plan), "iteration": 0,
                                    "max_iterations": request.stage_cap(), "energies": {}, "elapsed_s": 0.0,
                                    "left_s": None, "looks": None, "phase": "design"}
        self.write(force=True)

    def stage_index(self, stage: str) -> int:
        """0-based index of ``stage`` in the plan that runs; a stage only one plan has settles which runs."""
        if stage not in self.plan:
            self.plan = next((plan for plan in self.plans if stage in plan), self.plan)
            self.doc["stages"] = len(self.plan)
        return self.plan.index(stage) if stage in self.plan else 0

    def write(self, force: bool = False) -> None:
        now = time.perf_counter()
        if not force and now - self.last < 1.0 / WRITES_PER_S:
            return
        self.last = now
        self.doc["elapsed_s"] = round(now - self.t0, 2)
        self.doc["updated"] = now_iso()
        try:
            write_json(self.folder / "progress.json", self.doc)
        except OSError as exc:  # a full disk: the design goes on (its checkpoint says so if it cannot)
            print(f"studio worker: progress.json not written: {exc}", file=sys.stderr)

    def progress(self, stage: str, it: int, max_it: int, energies: dict[str, float], _stage_s: float) -> None:
        if self.watch.gone():
            raise KeyboardInterrupt  # the server died: stop here, run_design saves the checkpoint
        si = self.stage_index(stage)
        elapsed = time.perf_counter() - self.t0
        done = (si + min(it, max_it) / max(max_it, 1)) / max(len(self.plan), 1)
        self.doc.update(stage=stage, stage_index=si, iteration=it, max_iterations=max_it,
                        energies={k: float(v) for k, v in energies.items()
                                  if k.startswith("E_") and isinstance(v, (int, float))},
                        # an estimate: a stage may stop early when it converges
                        left_s=round(elapsed * (1 - done) / done, 1) if done > 0.02 else None)
        self.write(force=stage != self.last_stage)
        self.last_stage = stage

    def look(self, stage: str, files: dict[str, Path], _elapsed_s: float) -> None:
        copied = {}
        for view, src in files.items():
            rel = f"looks/{stage}_{view}.png"
            write_bytes_atomic(self.folder / rel, Path(src).read_bytes())
            copied[view] = rel
        self.doc["looks"] = {"stage": stage, "files": copied}
        if any(stage in plan for plan in self.plans):
            self.doc.update(stage=stage, stage_index=min(self.stage_index(stage) + 1, len(self.plan)))
        self.write(force=True)

    def phase(self, name: str) -> None:
        self.doc.update(phase=name, left_s=None)
        self.write(force=True)


def _design_job(ws: Workspace, run_id: str, watch: _ParentWatch) -> None:
    """run_design (resuming from the checkpoint if there is one), then the quick verify; records the end."""
    folder = ws.runs / run_id
    try:
        from saucerfab.studio.options import design_request

        rec = ws.read_run(run_id)
        request = design_request(ws.for_user(owner_of(rec)), rec["options"])  # the owner's uploads
        out = folder / "design"
        reporter = _Reporter(folder, request, watch, ws.scrub)
        if not (out / "design.json").is_file():  # done before: a resume only has the verify left
            from saucerfab.workflow import run_design

            run_design(request, out, progress=reporter.progress, look=reporter.look, log_every_s=1.0 / WRITES_PER_S)
        note = None
        if rec["options"].get("verify", True):
            reporter.phase("verify")
            note = _verify(out, request, reporter)
    except (Interrupted, KeyboardInterrupt) as exc:
        why = ws.scrub(str(exc)) if isinstance(exc, Interrupted) else "stopped before the first stage began"
        print(f"studio worker: interrupted: {why}", file=sys.stderr)
        _end(ws, run_id, "interrupted", None)
        return
    except Exception as exc:
        if _STOP_ASKED:  # the interrupt surfaced as another error: still the stop that was asked for
            traceback.print_exc()
            print("studio worker: interrupted (the error above is how the stop surfaced)", file=sys.stderr)
            _end(ws, run_id, "interrupted", None)
            return
        if isinstance(exc, SaucerfabError):
            _end(ws, run_id, "failed", ws.scrub(str(exc)))
            return
        traceback.print_exc()  # a fault of saucerfab: the traceback stays in worker.log
        _end(ws, run_id, "failed", f"internal error ({type(exc).__name__}: {ws.scrub(str(exc))[:300]}); the "
                                   f"traceback is in runs/{run_id}/worker.log; please report it with that file")
        return
    if note:
        print(f"studio worker: {note}", file=sys.stderr)
    _end(ws, run_id, "done", notes=[note] if note else [])


def _verify(out: Path, request: Any, reporter: _Reporter) -> str | None:
    """The quick verify of a trial export (as ``saucerfab design`` does); returns a note when it was not made.

    A verify that fails leaves the design done (it is complete and can be
    exported); the note says why it is not verified.
    """
    from saucerfab.workflow import verify_design

    def progress(msg: str, fraction: float) -> None:
        reporter.doc.update(stage="verify", iteration=int(round(100 * fraction)), max_iterations=100)
        reporter.write()

    note = None
    try:
        verify_design(out, printer=request.printer, cup_diameter_mm=request.cup_diameter_mm,
                      record_times=request.record_times, progress=progress)
    except KeyboardInterrupt:
        note = "not verified: the verify was stopped; the design is complete without it"
    except SaucerfabError as exc:  # the design itself is complete; the report says why it was not verified
        note = f"not verified: {reporter.scrub(str(exc))}"
    except Exception as exc:  # a fault in the verify must not lose a finished design
        traceback.print_exc()
        note = f"not verified: internal error ({type(exc).__name__}); the traceback is in worker.log"
    return note


# --------------------------------------------------------------------------- export


def _set_export(ws: Workspace, run_id: str, printer: str, **fields: Any) -> None:
    def change(rec: dict[str, Any]) -> None:
        rec.setdefault("exports", {}).setdefault(printer, {}).update(fields)

    ws.update_run(run_id, change)


def zip_folder(folder: Path, dest: Path) -> None:
    """The files of ``folder`` (hidden ones left out) as one zip at ``dest``, written atomically."""
    import io

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in sorted(folder.rglob("*")):
            rel = p.relative_to(folder)
            if p.is_file() and not any(part.startswith(".") for part in rel.parts):
                zf.write(p, f"{folder.name}/{rel.as_posix()}")
    write_bytes_atomic(dest, buf.getvalue())


def _export_job(ws: Workspace, run_id: str, printer: str) -> None:
    """The workflow's make_print into ``exports/<printer>/``, then its zip; records the export."""
    folder = ws.runs / run_id
    out = folder / "exports" / printer
    try:
        from saucerfab.fabricate.options import FabOptions
        from saucerfab.fabricate.pipeline import export_lock
        from saucerfab.model.profiles import load_profile
        from saucerfab.workflow import make_print

        entry = ws.read_run(run_id).get("exports", {}).get(printer, {})
        profile = load_profile(printer)
        out.parent.mkdir(exist_ok=True)
        with export_lock(out):
            done = make_print(folder / "design", out, printer=profile, formats=entry.get("formats"),
                              options=FabOptions())
        result = done.export
        zip_folder(out, folder / "exports" / f"{printer}.zip")
        files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*")
                       if p.is_file() and not any(s.startswith(".") for s in p.relative_to(out).parts))
        checked = [c.report for c in done.checks if c.report is not None]
        _set_export(ws, run_id, printer, status="done", error=None, finished=now_iso(), formats=list(result.formats),
                    printable=all(r.exit_code == 0 for r in checked) if checked else None, files=files,
                    zip=f"exports/{printer}.zip", warnings=list(result.warnings), notes=list(done.notes))
    except KeyboardInterrupt:
        _set_export(ws, run_id, printer, status="failed", error="the export was stopped; start it again")
    except SaucerfabError as exc:
        _set_export(ws, run_id, printer, status="failed", error=ws.scrub(str(exc)))
    except Exception as exc:
        traceback.print_exc()
        _set_export(ws, run_id, printer, status="failed",
                    error=f"internal error ({type(exc).__name__}); the traceback is in runs/{run_id}/worker.log")
    finally:
        if (out.is_dir() and not (out / "export.json").is_file()):
            shutil.rmtree(out, ignore_errors=True)  # nothing half made is left to download



if __name__ == "__main__":  # a job on a Dask worker (saucerfab.studio.cluster.run_job): ROOT KIND RUN_ID [PRINTER]
    main(*sys.argv[1:5])
