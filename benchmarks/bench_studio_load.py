"""The studio shared by a team, under load: N designers at once against a real ``saucerfab studio`` (issue 39).

    .venv/bin/python benchmarks/bench_studio_load.py [--designers 8] [--runs 3] [--jobs 2] [--dask-workers 2]
        [--no-dask] [--no-restart] [--out benchmarks/results/studio_load.txt]

Loopback only, bounded in count and time (``--phase-timeout-s`` per phase).
Each simulated designer has their own token (a token file of ``USER:TOKEN``
lines) and, all at once (a thread each, httpx): uploads two small pictures of
their own, starts ``--runs`` tiny designs (cancelling the last one at once
when their number is odd: "cancelled as asked"), watches them (the run's JSON
and the page, as a browser would), exports the first for the j55 profile and
downloads its zip. Phases:

* ``local``: ``saucerfab studio --jobs 2`` (worker processes);
* ``dask``: ``--scheduler`` on a ``--dask-workers`` Dask LocalCluster (processes,
  one thread each) started by this script;
* ``restart``: local again; once about half the designs have ended (and one
  is running) the server gets SIGTERM (as a service manager stops it), then starts again on the same
  workspace; each designer resumes their interrupted runs.

Checks and figures per phase: every run ends as asked (done, or cancelled);
0 lost (every run the designers started is listed and final); 0 mixed up
(each run's owner is its designer, and the input pictures' sha256 in its
``design.json`` are the designer's own uploads); p50/p95 latency of the API
(JSON routes) and of the page (``/`` and its script) under load; the time
from starting a design to its first look. The log (``--out``) has the table
and every run's outcome.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

try:
    import httpx2 as httpx  # the installed name of httpx here (starlette's test client uses it too)
except ImportError:  # pragma: no cover
    import httpx  # type: ignore[no-redef]

ROOT = Path(__file__).resolve().parents[1]
#: a tiny design: a 16 x 16 grid, 32 px views, a few iterations a stage, no verify
TINY = {"resolution": 16, "image_size": 32, "max_iters": 4, "verify": False, "record_times": False}
FINAL = ("done", "failed", "cancelled", "interrupted")
#: seconds between a designer's looks at their runs (a page's event stream polls a file 4 times a second)
POLL_S = 0.5


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def picture(seed: int, size: int = 48) -> bytes:
    """A distinct small PNG: a coloured disc on white, different for each seed."""
    from PIL import Image

    yy, xx = np.mgrid[0:size, 0:size]
    rng = np.random.default_rng(seed)
    img = np.full((size, size, 3), 255, np.uint8)
    r = size * (0.2 + 0.2 * rng.random())
    img[(yy - size / 2) ** 2 + (xx - size / 2) ** 2 < r * r] = rng.integers(0, 160, 3)
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


@dataclass
class Timings:
    """Latencies by kind ("api", "page"), seconds; shared by the designers' threads."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    samples: dict[str, list[float]] = field(default_factory=dict)

    def add(self, kind: str, seconds: float) -> None:
        with self.lock:
            self.samples.setdefault(kind, []).append(seconds)

    def pct(self, kind: str, q: float) -> float:
        xs = sorted(self.samples.get(kind, []))
        return xs[min(len(xs) - 1, int(round(q * (len(xs) - 1))))] if xs else float("nan")


class Designer:
    """One simulated designer: their token, client, uploads and runs."""

    def __init__(self, index: int, token: str, base: str, timings: Timings) -> None:
        self.name = f"designer{index}"
        self.index = index
        self.client = httpx.Client(base_url=base, headers={"Authorization": f"token {token}"}, timeout=60)
        self.timings = timings
        self.sha: dict[str, str] = {}  # role -> sha256 of what this designer uploaded
        self.runs: list[str] = []
        self.asked: dict[str, str] = {}  # run id -> the end asked ("done" or "cancelled")
        self.started: dict[str, float] = {}
        self.first_look: dict[str, float] = {}
        self.errors: list[str] = []

    def call(self, method: str, path: str, kind: str = "api", **kw: Any) -> Any:
        t0 = time.perf_counter()
        r = self.client.request(method, path, **kw)
        self.timings.add(kind, time.perf_counter() - t0)
        return r

    def upload_pictures(self) -> dict[str, str]:
        ids = {}
        for role, seed in (("direct", 2 * self.index), ("reflected", 2 * self.index + 1)):
            data = picture(1000 + seed)
            self.sha[role] = hashlib.sha256(data).hexdigest()
            r = self.call("POST", f"/api/uploads?role={role}&name={self.name}-{role}.png", content=data)
            if r.status_code != 201:
                raise RuntimeError(f"{self.name}: upload {r.status_code} {r.text[:200]}")
            ids[role] = r.json()["id"]
        return ids

    def start_runs(self, n: int, cancel_last: bool) -> None:
        ids = self.upload_pictures()
        for i in range(n):
            r = self.call("POST", "/api/runs", json={**ids, **TINY, "title": f"{self.name} #{i}"})
            if r.status_code != 201:
                self.errors.append(f"create {r.status_code} {r.text[:200]}")
                continue
            run_id = r.json()["id"]
            self.runs.append(run_id)
            self.started[run_id] = time.perf_counter()
            self.asked[run_id] = "done"
        if cancel_last and self.runs:
            r = self.call("POST", f"/api/runs/{self.runs[-1]}/cancel")
            if r.status_code == 200:
                self.asked[self.runs[-1]] = "cancelled"

    def watch(self, deadline: float, stop: threading.Event | None = None) -> dict[str, dict[str, Any]]:
        """Look at the runs (and now and then the page) until each is final; the last record of each."""
        last: dict[str, dict[str, Any]] = {}
        n = 0
        while time.monotonic() < deadline and not (stop is not None and stop.is_set()):
            n += 1
            if n % 4 == 1:  # the page, as a browser reloading it
                self.call("GET", "/", kind="page", headers={"Accept": "text/html"})
                self.call("GET", "/static/studio.js", kind="page")
            busy = False
            for run_id in self.runs:
                if last.get(run_id, {}).get("status") in FINAL:
                    continue
                try:
                    r = self.call("GET", f"/api/runs/{run_id}")
                except httpx.TransportError:  # the server is restarting
                    busy = True
                    continue
                if r.status_code != 200:
                    busy = True
                    continue
                rec = r.json()
                last[run_id] = rec
                looks = (rec.get("progress") or {}).get("looks")
                if run_id not in self.first_look and (looks or rec.get("status") == "done"):
                    self.first_look[run_id] = time.perf_counter() - self.started[run_id]
                busy = busy or rec.get("status") not in FINAL
            if not busy:
                break
            time.sleep(POLL_S)
        return last

    def export_first(self, deadline: float) -> str:
        """Export the first done run for j55, wait, download its zip; returns "ok" or what went wrong."""
        done = [i for i in self.runs if self.asked[i] == "done"]
        if not done:
            return "no run to export"
        run_id = done[0]
        r = self.call("POST", f"/api/runs/{run_id}/exports", json={"printer": "j55"})
        if r.status_code != 202:
            return f"export {r.status_code} {r.text[:200]}"
        while time.monotonic() < deadline:
            entry = self.call("GET", f"/api/runs/{run_id}").json().get("exports", {}).get("j55", {})
            if entry.get("status") not in ("queued", "running"):
                break
            time.sleep(POLL_S)
        if entry.get("status") != "done":
            return f"export {entry.get('status')}: {entry.get('error')}"
        z = self.call("GET", f"/api/runs/{run_id}/exports/j55.zip", kind="download")
        if z.status_code != 200:
            return f"zip {z.status_code}"
        with zipfile.ZipFile(io.BytesIO(z.content)) as zf:
            return "ok" if zf.namelist() else "empty zip"

    def check_mine(self, run_id: str) -> str | None:
        """None when run ``run_id`` is this designer's with their pictures; else what is wrong."""
        rec = self.call("GET", f"/api/runs/{run_id}").json()
        if rec.get("owner") != self.name:
            return f"owner {rec.get('owner')}"
        if rec.get("status") != "done":
            return None  # nothing designed to compare
        d = self.call("GET", f"/api/runs/{run_id}/files/design/design.json")
        if d.status_code != 200:
            return f"design.json {d.status_code}"
        inputs = d.json().get("inputs", {})
        got = {role: (inputs.get(role) or {}).get("sha256") for role in ("direct", "reflected")}
        return None if got == self.sha else f"inputs {got} are not {self.sha}"


def start_server(ws: Path, tokens: Path, port: int, jobs: int, log: Path, scheduler: str | None) -> Any:
    env = {k: v for k, v in os.environ.items() if k != "SAUCERFAB_STUDIO_TOKEN"} | {"PYTHONUNBUFFERED": "1"}
    cmd = [sys.executable, "-m", "saucerfab", "studio", "--workspace", str(ws), "--port", str(port),
           "--token-file", str(tokens), "--jobs", str(jobs)] + (["--scheduler", scheduler] if scheduler else [])
    out = log.open("ab")
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"saucerfab studio exited with {proc.returncode}: {log.read_text()[-2000:]}")
        try:
            if httpx.get(f"http://127.0.0.1:{port}/api/session", timeout=2).status_code in (200, 401):
                return proc
        except httpx.TransportError:
            pass
        time.sleep(0.3)
    proc.kill()
    raise RuntimeError("saucerfab studio did not answer within 120 s")


def stop_server(proc: Any, timeout_s: float = 60) -> float:
    """SIGTERM (as a service manager stops it); returns the seconds it took to exit."""
    t0 = time.perf_counter()
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    return time.perf_counter() - t0


def run_phase(name: str, args: argparse.Namespace, scheduler: str | None, log: list[str]) -> dict[str, Any]:
    """One phase (see the module docstring); returns its row of figures."""
    tmp = Path(tempfile.mkdtemp(prefix=f"studio-load-{name}-"))
    ws = tmp / "ws"
    tokens = {f"designer{i}": f"token-of-designer-{i}-{os.urandom(8).hex()}" for i in range(args.designers)}
    token_file = tmp / "tokens.txt"
    token_file.write_text("".join(f"{u}:{t}\n" for u, t in tokens.items()) + f"admin:admin-{os.urandom(12).hex()}\n")
    port = free_port()
    server_log = tmp / "server.log"
    timings = Timings()
    t0 = time.perf_counter()
    proc = start_server(ws, token_file, port, args.jobs, server_log, scheduler)
    base = f"http://127.0.0.1:{port}"
    designers = [Designer(i, tokens[f"designer{i}"], base, timings) for i in range(args.designers)]
    deadline = time.monotonic() + args.phase_timeout_s
    restart = name == "restart"
    results: dict[str, dict[str, Any]] = {}
    exports: dict[str, str] = {}
    at_kill: dict[str, int] = {}

    def designer_flow(d: Designer) -> None:
        try:
            d.start_runs(args.runs, cancel_last=(not restart and d.index % 2 == 1))
            if restart:
                return
            results.update(d.watch(deadline))
            exports[d.name] = d.export_first(deadline)
        except Exception as exc:  # noqa: BLE001 - a designer's failure is a finding of the bench
            d.errors.append(f"{type(exc).__name__}: {exc}")

    threads = [threading.Thread(target=designer_flow, args=(d,)) for d in designers]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=max(1.0, deadline - time.monotonic()))
    restart_s = None
    if restart:
        # wait until about half the designs have ended, then stop the server mid-load and start it again
        every = [(d, r) for d in designers for r in d.runs]
        while time.monotonic() < deadline:
            states = [d.client.get(f"/api/runs/{r}").json()["status"] for d, r in every]
            # about half ended, and a design running: the restart has each kind of run to bring back
            if sum(s in FINAL for s in states) >= len(every) // 2 and "running" in states:
                break
            time.sleep(POLL_S)
        stop_s = stop_server(proc)
        states = [json.loads((ws / "runs" / r / "run.json").read_text())["status"] for _, r in every]
        at_kill = {s: states.count(s) for s in sorted(set(states))}
        log.append(f"restart: SIGTERM after {time.perf_counter() - t0:.1f} s; the server took {stop_s:.1f} s to "
                   f"stop; runs then: {at_kill}")
        t1 = time.perf_counter()
        proc = start_server(ws, token_file, port, args.jobs, server_log, scheduler)
        restart_s = time.perf_counter() - t1
        for d in designers:  # each designer resumes their interrupted runs (the queued ones come back by themselves)
            for r in d.runs:
                if d.call("GET", f"/api/runs/{r}").json()["status"] in ("interrupted",):
                    d.call("POST", f"/api/runs/{r}/resume")
        threads = [threading.Thread(target=lambda d=d: results.update(d.watch(deadline))) for d in designers]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=max(1.0, deadline - time.monotonic()))
    wall = time.perf_counter() - t0
    # the checks: as asked, lost, mixed up
    started = sum(len(d.runs) for d in designers)
    listed = {r["id"] for d in designers for r in d.call("GET", "/api/runs").json()}
    lost = [r for d in designers for r in d.runs if r not in listed or results.get(r, {}).get("status") not in FINAL]
    not_as_asked = [f"{r}: asked {d.asked[r]}, ended {results.get(r, {}).get('status')}"
                    for d in designers for r in d.runs if results.get(r, {}).get("status") != d.asked[r]]
    mixed = [f"{d.name} {r}: {why}" for d in designers for r in d.runs if (why := d.check_mine(r))]
    # another designer's run is not theirs to see
    peek = designers[-1].call("GET", f"/api/runs/{designers[0].runs[0]}").status_code if designers[0].runs else 404
    stop_s = stop_server(proc)
    looks = sorted(v for d in designers for v in d.first_look.values())
    ended = [results.get(r, {}).get("status") for d in designers for r in d.runs]
    row = {
        "phase": name, "designers": len(designers), "runs": started,
        "done": ended.count("done"), "cancelled": ended.count("cancelled"),
        "as_asked": started - len(not_as_asked), "lost": len(lost), "mixed": len(mixed) + (peek != 404),
        "exports_ok": sum(v == "ok" for v in exports.values()),
        "api_p50": timings.pct("api", 0.5), "api_p95": timings.pct("api", 0.95), "api_n": len(timings.samples.get("api", [])),
        "page_p50": timings.pct("page", 0.5), "page_p95": timings.pct("page", 0.95),
        "look_p50": statistics.median(looks) if looks else float("nan"), "look_max": max(looks, default=float("nan")),
        "wall_s": wall, "restart_s": restart_s, "at_kill": at_kill, "stop_s": stop_s,
    }
    log.append(f"{name}: {json.dumps(row, default=str)}")
    for d in designers:
        if d.errors:
            log.append(f"{name} {d.name} errors: {d.errors}")
        for r in d.runs:
            rec = results.get(r, {})
            log.append(f"{name} {d.name} {r} asked {d.asked[r]} ended {rec.get('status')} "
                       f"first look {d.first_look.get(r, float('nan')):.1f} s {(rec.get('error') or '')[:120]}")
    log += [f"{name} not as asked: {x}" for x in not_as_asked] + [f"{name} lost: {x}" for x in lost]
    log += [f"{name} mixed: {x}" for x in mixed] + [f"{name} exports: {exports}"]
    log.append(f"{name} server log tail:\n{server_log.read_text(errors='replace')[-1500:]}")
    if row["lost"] or row["mixed"] or row["as_asked"] != started or (not restart and row["exports_ok"] < len(designers)):
        log.append(f"{name}: the workspace is kept for a look: {tmp}")
    else:
        shutil.rmtree(tmp, ignore_errors=True)
    return row


def table(rows: list[dict[str, Any]]) -> str:
    head = ("| phase | runs (designers x runs) | ended as asked (done / cancelled) | lost | mixed up | exports + zip ok "
            "| API p50 / p95 ms | page p50 / p95 ms | first look p50 / max s | wall s |")
    out = [head, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        out.append(
            f"| {r['phase']} | {r['runs']} ({r['designers']} x {r['runs'] // max(r['designers'], 1)}) | "
            f"{r['as_asked']} ({r['done']} / {r['cancelled']}) | {r['lost']} | {r['mixed']} | "
            f"{r['exports_ok'] if r['phase'] != 'restart' else '-'} | "
            f"{1000 * r['api_p50']:.0f} / {1000 * r['api_p95']:.0f} | {1000 * r['page_p50']:.0f} / "
            f"{1000 * r['page_p95']:.0f} | {r['look_p50']:.1f} / {r['look_max']:.1f} | {r['wall_s']:.0f} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--designers", type=int, default=8)
    ap.add_argument("--runs", type=int, default=3, help="designs per designer (at most the studio's queue share, 4)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--dask-workers", type=int, default=2)
    ap.add_argument("--no-dask", action="store_true")
    ap.add_argument("--no-restart", action="store_true")
    ap.add_argument("--phase-timeout-s", type=float, default=600.0)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "studio_load.txt")
    args = ap.parse_args(argv)
    if not 1 <= args.designers <= 32 or not 1 <= args.runs <= 4:
        ap.error("--designers is 1 to 32 and --runs 1 to 4 (the bench stays bounded)")
    log = [f"bench_studio_load {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}: {vars(args)}",
           f"load average at start: {os.getloadavg()}, cores: {os.cpu_count()}"]
    rows = [run_phase("local", args, None, log)]
    if not args.no_dask:
        from distributed import LocalCluster

        with LocalCluster(n_workers=args.dask_workers, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster:
            rows.append(run_phase("dask", args, cluster.scheduler_address, log))
    if not args.no_restart:
        rows.append(run_phase("restart", args, None, log))
    log.append(f"load average at end: {os.getloadavg()}")
    text = table(rows)
    restart = next((r for r in rows if r["phase"] == "restart"), None)
    if restart:
        text += (f"\n\nRestart mid-load: runs when the server got SIGTERM {restart['at_kill']}; it came back in "
                 f"{restart['restart_s']:.1f} s, and every run ended done ({restart['done']} of {restart['runs']}; "
                 f"lost {restart['lost']}).")
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join([text, "", *log]) + "\n", encoding="utf-8")
    return 0 if all(r["lost"] == 0 and r["mixed"] == 0 and r["as_asked"] == r["runs"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
