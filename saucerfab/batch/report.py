"""Batch outcomes: ``batch-report.json``, ``batch-report.html``, the terminal table and live progress.

``batch-report.json`` (schema ``saucerfab.batch-report/1``)::

    {
      "schema": "saucerfab.batch-report/1",
      "state": "running" | "finished" | "interrupted",
      "manifest": "/abs/path/manifest.toml", "out": "/abs/path/out",
      "engine": "local process pool, 2 workers", "saucerfab_version": "0.1.0",
      "started": "2026-...Z", "finished": "2026-...Z" | null, "wall_s": 12.3,
      "summary": {"jobs": 7, "ok": 6, "failed": 1, "pending": 0, "reused": 2},
      "jobs": [
        {"id": "teapot", "kind": "design" | "raw",
         "status": "ok" | "failed" | "pending", "reused": false,
         "stage": null | "inputs" | "design" | "export" | "check" | "worker",
         "reason": null | "why it failed", "verdict": "printable" | "not printable" | "unreadable" | null,
         "times": {"design": s, "export": s, "check": s, "total": s},
         "output": "teapot", "files": ["export/teapot.3mf", ...],
         "checks": {"export/teapot.3mf": {"verdict": ..., "exit_code": 0, "findings": {...}}},
         "key": "<sha256>", "worker": "host:pid", "attempts": 1}
      ]
    }

The report is rewritten (atomically) as jobs finish, so a batch killed midway
still leaves an up-to-date report of the jobs it finished.
"""

from __future__ import annotations

import html
import json
import sys
import time
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from saucerfab import __version__
from saucerfab.batch.manifest import HTML_NAME, JSON_NAME
from saucerfab.files.fileio import write_text_atomic

REPORT_SCHEMA = "saucerfab.batch-report/1"


@dataclass
class JobOutcome:
    """One job's line in the report (see the module docstring for the fields)."""

    id: str
    kind: str
    status: str = "pending"
    reused: bool = False
    stage: str | None = None
    reason: str | None = None
    verdict: str | None = None
    times: dict[str, float] = field(default_factory=dict)
    output: str | None = None
    files: list[str] = field(default_factory=list)
    checks: dict[str, Any] = field(default_factory=dict)
    key: str = ""
    worker: str = ""
    attempts: int = 0
    trace: str | None = None


@dataclass
class BatchResult:
    """What :func:`saucerfab.batch.run_batch` returns."""

    out: Path
    outcomes: list[JobOutcome]
    engine: str
    wall_s: float
    state: str = "finished"

    @property
    def ok(self) -> bool:
        """Every job ran (or was found complete) and passed its check."""
        return all(o.status == "ok" for o in self.outcomes)

    @property
    def exit_code(self) -> int:
        """0 if every job is ok, 1 otherwise."""
        return 0 if self.ok else 1

    @property
    def report_json(self) -> Path:
        return self.out / JSON_NAME

    @property
    def report_html(self) -> Path:
        return self.out / HTML_NAME

    def outcome(self, job_id: str) -> JobOutcome:
        for o in self.outcomes:
            if o.id == job_id:
                return o
        raise KeyError(job_id)


def summary(outcomes: list[JobOutcome]) -> dict[str, int]:
    return {
        "jobs": len(outcomes),
        "ok": sum(o.status == "ok" for o in outcomes),
        "failed": sum(o.status == "failed" for o in outcomes),
        "pending": sum(o.status == "pending" for o in outcomes),
        "reused": sum(o.reused for o in outcomes),
    }


def _iso(t: float | None) -> str | None:
    if t is None:
        return None
    return datetime.fromtimestamp(t, tz=timezone.utc).isoformat(timespec="seconds").replace("+00:00", "Z")


def report_dict(
    outcomes: list[JobOutcome],
    *,
    manifest: Path,
    out: Path,
    engine: str,
    started: float,
    finished: float | None,
    state: str,
) -> dict[str, Any]:
    now = finished if finished is not None else time.time()
    return {
        "schema": REPORT_SCHEMA,
        "state": state,
        "manifest": str(manifest),
        "out": str(out),
        "engine": engine,
        "saucerfab_version": __version__,
        "python": sys.version.split()[0],
        "started": _iso(started),
        "finished": _iso(finished),
        "wall_s": round(now - started, 3),
        "summary": summary(outcomes),
        "jobs": [{k: v for k, v in asdict(o).items() if not (k == "trace" and v is None)} for o in outcomes],
    }


#: inline styles of the status and verdict cells (the page's own CSS is the shared report page's)
_STYLE = {
    "ok": "color:#176b2c;font-weight:600", "failed": "color:#b00020;font-weight:600", "pending": "color:#666",
    "printable": "color:#176b2c", "not printable": "color:#b00020", "unreadable": "color:#b00020",
}
_NUM = ' style="text-align:right;font-variant-numeric:tabular-nums"'


def _style(key: str) -> str:
    return f' style="{_STYLE[key]}"' if key in _STYLE else ""


def _job_row(j: dict[str, Any]) -> str:
    """One job's table row: id, kind, status, check verdict, reason, times and links to its files."""
    e = html.escape
    times = j.get("times") or {}

    def t(k: str) -> str:
        return f"{times[k]:.2f}" if k in times else ""

    files = "".join(
        f'<a href="{e(j["output"] + "/" + f)}">{e(f)}</a><br>'
        for f in j.get("files", [])
        if j.get("output") and f.startswith("export/") and "/" not in f[len("export/"):]
        and not f.endswith((".png", ".mtl", ".json", ".html"))
    )
    for page, label in (("export/report.html", "print report"), ("design/report.html", "design report")):
        if j.get("output") and page in j.get("files", []):
            files += f'<a href="{e(j["output"] + "/" + page)}">{label}</a><br>'
    preview = "design/previews/composite.png"
    if j.get("output") and preview in j.get("files", []):
        src = e(j["output"] + "/" + preview)
        files += f'<a href="{src}"><img src="{src}" alt="preview" height="64"></a>'
    reason = e(j.get("reason") or "")
    if j.get("stage") and j.get("status") == "failed":
        reason = f"<b>{e(j['stage'])}</b>: {reason}"
    if j.get("trace"):
        reason += f"<details><summary>traceback</summary><pre>{e(j['trace'])}</pre></details>"
    status = e(j["status"]) + (" (reused)" if j.get("reused") else "")
    verdict = j.get("verdict") or ""
    return (
        "<tr>"
        f"<td><code>{e(j['id'])}</code></td><td>{e(j['kind'])}</td>"
        f"<td{_style(j['status'])}>{status}</td>"
        f"<td{_style(verdict)}>{e(verdict)}</td>"
        f"<td>{reason}</td>"
        f"<td{_NUM}>{t('design')}</td><td{_NUM}>{t('export')}</td>"
        f"<td{_NUM}>{t('check')}</td><td{_NUM}>{t('total')}</td>"
        f"<td>{files}</td></tr>"
    )


def report_html(data: dict[str, Any]) -> str:
    """A self-contained HTML page for a report dict (no scripts, no outside files): :func:`saucerfab.imaging.panels.html_report`."""
    from saucerfab.pages.html import Section, html_report

    s = data["summary"]
    batch = {
        "manifest": data["manifest"],
        "output": data["out"],
        "engine": data["engine"],
        "saucerfab": data["saucerfab_version"],
        "started": data["started"],
        "state": data["state"],
        "wall time": f"{data['wall_s']:.1f} s",
    }
    counts = (
        f"<p>{s['jobs']} jobs: <span{_style('ok')}>{s['ok']} ok</span>, "
        f"<span{_style('failed')}>{s['failed']} failed</span>, <span{_style('pending')}>{s['pending']} pending</span>, "
        f"{s['reused']} reused from an earlier run</p>\n"
    )
    table = (
        "<table><thead><tr><th>job</th><th>kind</th><th>status</th><th>check</th><th>reason</th>"
        + "".join(f'<th style="white-space:nowrap">{h} s</th>' for h in ("design", "export", "check", "total"))
        + "<th>print files</th></tr></thead>\n<tbody>\n"
        + "\n".join(_job_row(j) for j in data["jobs"])
        + "\n</tbody></table>"
    )
    return html_report([Section("Batch", table=batch), Section("Jobs", html=counts + table)],
                       title="saucerfab batch report")


def write_reports(data: dict[str, Any], out: Path) -> None:
    """Write ``batch-report.json`` and ``batch-report.html`` into ``out`` atomically
    (with the usual file mode: umask applies)."""
    for name, text in ((JSON_NAME, json.dumps(data, indent=2) + "\n"), (HTML_NAME, report_html(data))):
        write_text_atomic(out / name, text)


# --------------------------------------------------------------------------- terminal


def _fmt_s(v: float | None) -> str:
    return "" if v is None else f"{v:.1f}"


def print_table(outcomes: list[JobOutcome], console: Any = None) -> None:
    """The final per-job table (rich)."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = console or Console(stderr=False)
    table = Table(title="saucerfab batch", show_lines=False)
    for col, kw in (
        ("job", {}),
        ("status", {}),
        ("check", {}),
        ("total s", {"justify": "right"}),
        ("reason", {"overflow": "fold"}),
    ):
        table.add_column(col, **kw)
    style = {"ok": "green", "failed": "bold red", "pending": "dim"}
    for o in outcomes:
        status = o.status + (" (reused)" if o.reused else "")
        reason = f"{o.stage}: {o.reason}" if o.status == "failed" and o.stage else (o.reason or "")
        table.add_row(
            escape(o.id),
            f"[{style.get(o.status, 'default')}]{status}[/]",
            o.verdict or "",
            _fmt_s(o.times.get("total")),
            escape(reason),
        )
    console.print(table)
    s = summary(outcomes)
    console.print(
        f"{s['jobs']} jobs: [green]{s['ok']} ok[/], [red]{s['failed']} failed[/], "
        f"{s['pending']} pending, {s['reused']} reused from an earlier run"
    )


class NullDisplay:
    """No live output (``--quiet``)."""

    def start(self, total: int, reused: int) -> None: ...
    def queued(self, job_id: str) -> None: ...
    def stage(self, job_id: str, stage: str) -> None: ...
    def done(self, outcome: JobOutcome) -> None: ...
    def note(self, text: str) -> None: ...
    def close(self) -> None: ...


class LineDisplay(NullDisplay):
    """One line per finished job (logs, CI, no terminal)."""

    def __init__(self, stream: Any = None) -> None:
        self.stream = stream or sys.stderr
        self.total = 0
        self.count = 0

    def start(self, total: int, reused: int) -> None:
        self.total = total
        self.count = reused
        print(f"batch: {total} jobs, {reused} already complete", file=self.stream, flush=True)

    def done(self, outcome: JobOutcome) -> None:
        self.count += 1
        extra = f" ({outcome.stage}: {outcome.reason})" if outcome.status == "failed" else ""
        verdict = f" check {outcome.verdict}" if outcome.verdict else ""
        print(
            f"[{self.count}/{self.total}] {outcome.id}: {outcome.status}{verdict}"
            f" {outcome.times.get('total', 0):.1f}s{extra}",
            file=self.stream,
            flush=True,
        )

    def note(self, text: str) -> None:
        print(text, file=self.stream, flush=True)


class RichDisplay(NullDisplay):
    """One overall progress bar, the running jobs with their stage, a line per finished job."""

    def __init__(self, console: Any = None) -> None:
        from rich.console import Console

        self.console = console or Console(stderr=True)
        self.running: dict[str, tuple[str, float]] = {}
        self.live: Any = None

    def _render(self) -> Any:
        from rich.console import Group
        from rich.markup import escape
        from rich.table import Table

        table = Table.grid(padding=(0, 2))
        now = time.monotonic()
        for job_id, (stage, since) in list(self.running.items())[:12]:
            table.add_row(f"[cyan]{escape(job_id)}[/]", stage, f"{now - since:5.1f}s")
        more = len(self.running) - 12
        if more > 0:
            table.add_row(f"... and {more} more", "", "")
        return Group(self.progress, table)

    def start(self, total: int, reused: int) -> None:
        from rich.live import Live
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self.progress = Progress(
            TextColumn("[bold]batch"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=self.console,
        )
        self.task = self.progress.add_task("jobs", total=total, completed=reused)
        if reused:
            self.console.print(f"{reused} of {total} jobs already complete (unchanged inputs): reused")
        self.live = Live(get_renderable=self._render, console=self.console, refresh_per_second=4, transient=True)
        self.live.start()

    def queued(self, job_id: str) -> None:
        self.running[job_id] = ("queued", time.monotonic())

    def stage(self, job_id: str, stage: str) -> None:
        if job_id in self.running:
            self.running[job_id] = (stage, self.running[job_id][1])

    def done(self, outcome: JobOutcome) -> None:
        from rich.markup import escape

        self.running.pop(outcome.id, None)
        self.progress.advance(self.task)
        if outcome.status == "ok":
            mark = "[green]ok[/]"
        else:
            mark = f"[bold red]failed[/] ({outcome.stage}: {escape(outcome.reason or '')})"
        verdict = f" check {outcome.verdict}" if outcome.verdict else ""
        self.console.print(f"{outcome.id}: {mark}{verdict} {outcome.times.get('total', 0):.1f}s", highlight=False)

    def note(self, text: str) -> None:
        self.console.print(text, highlight=False)

    def close(self) -> None:
        if self.live is not None:
            self.live.stop()
            self.live = None
