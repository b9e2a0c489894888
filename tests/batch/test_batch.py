"""``saucerfab batch`` end to end: real design, export and check on tiny jobs.

One small batch (design folders, a raw-input job designed at a tiny size, a
broken upload) is run once in this process as the reference; the local
process pool, a Dask ``LocalCluster``, a killed-and-resumed batch and a
second run of the same jobs must all give the same bytes.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import pytest

from saucerfab.batch import load_manifest, plan_batch, run_batch, run_job
from saucerfab.batch.jobs import MARKER, completed, read_marker
from saucerfab.batch.report import HTML_NAME, JSON_NAME, LineDisplay
from saucerfab.batch.runner import LOCK_NAME, _locked
from saucerfab.cli import main
from saucerfab.errors import ConfigError
from saucerfab.model.design_folder import save_design, synthetic_design

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "samples" / "batch"
DESIGN_JOBS = ["waves-j55", "waves-j850-100mm", "ripples-mimaki", "bowl-j55"]
RAW_JOBS = ["ring-star", "fish-moon-dome"]
RAW_JOB = "ring-star"
BAD_JOB = "broken-upload"
GOOD_JOBS = [*DESIGN_JOBS, *RAW_JOBS]
ALL_JOBS = [*GOOD_JOBS, BAD_JOB]  # manifest order
#: the sample manifest's defaults, made tiny so the tests stay fast
FAST = {
    "export_options = { texture_px = 256 }": "export_options = { texture_px = 64 }",
    "design_options = { resolution = 24, image_size = 32, max_iters = 20 }": (
        "design_options = { resolution = 12, image_size = 16, max_iters = 4 }"
    ),
}


def fast_sample_manifest() -> str:
    text = (SAMPLE / "manifest.toml").read_text(encoding="utf-8")
    for slow, fast in FAST.items():
        assert slow in text, slow
        text = text.replace(slow, fast)
    return text


MANIFEST = fast_sample_manifest()


def make_batch(folder: Path, manifest: str = MANIFEST) -> Path:
    """A copy of samples/batch (design folders, images, shape, scene) with ``manifest``."""
    import shutil

    shutil.copytree(
        SAMPLE, folder, ignore=shutil.ignore_patterns("manifest.*", "*.py", "*.md", "__pycache__"), dirs_exist_ok=True
    )
    (folder / "manifest.toml").write_text(manifest, encoding="utf-8")
    return folder / "manifest.toml"


def job_files(out: Path) -> dict[str, bytes]:
    """Every file of every job folder (not the reports), by path."""
    files = {}
    for job in sorted(p for p in out.iterdir() if p.is_dir() and not p.name.startswith(".")):
        for p in sorted(job.rglob("*")):
            if p.is_file():
                files[p.relative_to(out).as_posix()] = p.read_bytes()
    return files


# run_design records wall-clock times in three files of the design folder it
# writes (design.json metrics, energy_log.jsonl, the energies-over-time plot),
# so those differ between two runs of the same design request; the job's
# job.json lists their sha256. Everything else must be byte-identical, and
# these files must be identical once the times are taken out.
TIMED = ("design/design.json", "design/energy_log.jsonl", "design/previews/energies.png")


def _untimed(x: object) -> object:
    if isinstance(x, dict):
        return {
            k: _untimed(v)
            for k, v in x.items()
            if not (k.endswith("_s") or k in ("seconds", "seconds_per_iteration") or k in TIMED or k in [t.removeprefix("design/") for t in TIMED])
        }
    if isinstance(x, list):
        return [_untimed(v) for v in x]
    return x


def comparable(files: dict[str, bytes]) -> dict[str, bytes]:
    out = {}
    for name, data in files.items():
        rel = name.split("/", 1)[1]
        if rel == "design/previews/energies.png":
            data = b"(plot over wall-clock time)"
        elif rel == "design/energy_log.jsonl":
            data = b"\n".join(json.dumps(_untimed(json.loads(ln))).encode() for ln in data.splitlines())
        elif rel in ("design/design.json", MARKER):
            data = json.dumps(_untimed(json.loads(data))).encode()
        out[name] = data
    return out


def assert_same_files(a: dict[str, bytes], b: dict[str, bytes]) -> None:
    assert sorted(a) == sorted(b)
    timed = [k for k in a if k.split("/", 1)[1] in TIMED or k.endswith("/" + MARKER)]
    exact = [k for k in a if k not in timed and a[k] != b[k]]
    assert not exact, f"files differ: {exact}"
    ca, cb = comparable(a), comparable(b)
    differ = [k for k in timed if ca[k] != cb[k]]
    assert not differ, f"files differ beyond the design's recorded times: {differ}"


def assert_no_temporaries(out: Path) -> None:
    left = [p.name for p in out.rglob("*") if p.name.endswith((".part", ".old")) or p.name == ".batch-tmp"]
    assert not left, left


@pytest.fixture(scope="module")
def batch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_batch(tmp_path_factory.mktemp("batch"))


@pytest.fixture(scope="module")
def reference(batch: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    """The batch run once in this process: the bytes every other run must match."""
    out = tmp_path_factory.mktemp("ref") / "out"
    result = run_batch(batch, out, workers=0)
    return out, result


def test_reference_outcomes(reference: tuple[Path, object]) -> None:
    out, result = reference
    assert result.exit_code == 1  # the broken upload
    for job_id in GOOD_JOBS:
        o = result.outcome(job_id)
        assert o.status == "ok", (job_id, o.reason)
        assert o.verdict == "printable"
        assert not o.reused and o.times["total"] > 0
        marker = read_marker(out / job_id)
        assert marker and marker["complete"] and marker["status"] == "ok"
        assert completed(out, job_id, marker["key"]) is not None
        exported = [f for f in marker["files"] if f.startswith("export/")]
        assert "export/scene.json" in exported
        checks = [f for f in marker["files"] if f.startswith("check/")]
        assert checks and all(json.loads((out / job_id / c).read_text())["verdict"] == "printable" for c in checks)
    for job_id in RAW_JOBS:
        assert "design" in result.outcome(job_id).times
        assert (out / job_id / "design" / "design.json").is_file()
    inputs = json.loads((out / "fish-moon-dome" / "design" / "design.json").read_text())["inputs"]
    assert inputs["shape"]["file"] == "dome.npy"  # the job's shape file reached the design, by its name
    assert inputs["direct"]["file"] == "fish.png"
    bowl = {f.split("/")[-1] for f in result.outcome("bowl-j55").files}
    assert bowl >= {"saucer.3mf", "saucer.ply", "saucer.wrl", "saucer.3mf.json", "saucer.ply.json", "saucer.wrl.json"}
    assert any(f.endswith(".zip") for f in result.outcome("ripples-mimaki").files)
    assert "check/saucer.zip/saucer.obj.json" in result.outcome("ripples-mimaki").files
    bad = result.outcome(BAD_JOB)
    assert bad.status == "failed" and bad.stage == "design"
    assert "'images/broken.png'" in bad.reason and "truncated" in bad.reason  # the user's path, not a scratch copy
    assert read_marker(out / BAD_JOB)["complete"] is False
    assert sorted(p.name for p in (out / BAD_JOB).iterdir()) == [MARKER]
    report = json.loads((out / JSON_NAME).read_text())
    assert report["state"] == "finished"
    assert report["summary"] == {"jobs": 7, "ok": 6, "failed": 1, "pending": 0, "reused": 0}
    assert [j["id"] for j in report["jobs"]] == ALL_JOBS
    html = (out / HTML_NAME).read_text()
    assert "broken-upload" in html and "truncated" in html and "<script" not in html
    assert f'<img src="{RAW_JOB}/design/previews/composite.png"' in html  # the design's preview
    # each job's print report (and a raw job's design report) is linked, and is there
    for job_id in GOOD_JOBS:
        assert f'href="{job_id}/export/report.html">print report' in html, job_id
        assert (out / job_id / "export" / "report.html").is_file()
        assert (out / job_id / "export" / "verify" / "verify.json").is_file() or "not verified" in (
            out / job_id / "export" / "report.html").read_text(encoding="utf-8").lower()
    assert f'href="{RAW_JOB}/design/report.html">design report' in html
    raw_verify = json.loads((out / RAW_JOB / "export" / "verify" / "verify.json").read_text())
    assert raw_verify["files"][0]["views"][0]["eye"] == "design" and "seconds" not in raw_verify
    assert_no_temporaries(out)


def test_rerun_skips_unchanged_and_runs_changed(batch: Path, reference: tuple[Path, object], tmp_path: Path) -> None:
    import shutil

    out = tmp_path / "out"
    shutil.copytree(reference[0], out)
    before = {j: (out / j / MARKER).stat().st_mtime_ns for j in ALL_JOBS}
    again = run_batch(batch, out, workers=0)
    for j in GOOD_JOBS:
        assert again.outcome(j).reused and again.outcome(j).status == "ok"
        assert (out / j / MARKER).stat().st_mtime_ns == before[j]  # not rewritten
    assert not again.outcome(BAD_JOB).reused and again.outcome(BAD_JOB).status == "failed"
    assert json.loads((out / JSON_NAME).read_text())["summary"]["reused"] == 6

    # change a design folder (another seed): the job made from it runs again
    folder = tmp_path / "copy"
    shutil.copytree(batch.parent, folder)
    save_design(synthetic_design(shape="ripples", seed=5, resolution=24, texture_size=64), folder / "designs/ripples")
    changed = run_batch(folder / "manifest.toml", out, workers=0)
    rerun = {j for j in ALL_JOBS if not changed.outcome(j).reused}
    assert rerun == {"ripples-mimaki", BAD_JOB}
    assert changed.outcome("ripples-mimaki").status == "ok"
    # a changed parameter (printer) changes the key, too
    m = load_manifest(folder / "manifest.toml")
    plan = {p.job.id: p for p in plan_batch(m, out)}
    assert plan["waves-j55"].action == "reuse" and plan["waves-j850-100mm"].action == "reuse"
    text = MANIFEST.replace('printer = "j850"\ncup_diameter_mm = 100', 'printer = "j55"\ncup_diameter_mm = 100')
    assert text != MANIFEST
    (folder / "manifest.toml").write_text(text)
    plan = {p.job.id: p for p in plan_batch(load_manifest(folder / "manifest.toml"), out)}
    assert plan["waves-j850-100mm"].action == "run" and plan["waves-j55"].action == "reuse"
    # damaged output (a file edited after the run) is not complete any more
    target = next((out / "waves-j55" / "export").glob("*.3mf"))
    target.write_bytes(target.read_bytes()[:-1])
    plan = {p.job.id: p for p in plan_batch(load_manifest(folder / "manifest.toml"), out)}
    assert plan["waves-j55"].action == "run"


def test_run_job_is_deterministic(batch: Path, reference: tuple[Path, object], tmp_path: Path) -> None:
    """The same job again (design included), in a fresh output folder: byte-identical
    files. (The pool, cluster and resume tests compare whole batches the same way.)"""
    m = load_manifest(batch)
    out = tmp_path / "out"
    for job_id in ("fish-moon-dome", "bowl-j55"):
        result, reused = run_job(m.job(job_id), m.root, out, force=True)
        assert result.status == "ok" and not reused
        again = {k: v for k, v in job_files(out).items() if k.startswith(job_id + "/")}
        ref = {k: v for k, v in job_files(reference[0]).items() if k.startswith(job_id + "/")}
        assert_same_files(again, ref)
    result, reused = run_job(m.job("fish-moon-dome"), m.root, out)
    assert reused and result.status == "ok"


class Recorder(LineDisplay):
    """A line display that also keeps the stage events workers report."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.stages: list[tuple[str, str]] = []
        super().__init__(self)

    def write(self, s: str) -> None:
        self.lines.append(s)

    def flush(self) -> None:
        pass

    def stage(self, job_id: str, stage: str) -> None:
        self.stages.append((job_id, stage.split()[0]))


def test_local_pool_same_outputs(batch: Path, reference: tuple[Path, object], tmp_path: Path) -> None:
    out = tmp_path / "out"
    rec = Recorder()
    result = run_batch(batch, out, workers=2, display=rec)
    assert result.exit_code == 1
    assert result.engine == "local process pool, 2 workers"
    assert_same_files(job_files(out), job_files(reference[0]))
    workers = {result.outcome(j).worker.split(":")[1] for j in ALL_JOBS}
    assert str(os.getpid()) not in workers  # ran in the pool's processes
    text = "".join(rec.lines)
    assert "7 jobs" in text and "broken-upload: failed" in text and "waves-j55: ok" in text
    # per-job status: workers report each stage as it starts
    assert {s for j, s in rec.stages if j == RAW_JOB} == {"design", "export", "check", "verify"}
    assert {s for j, s in rec.stages if j == "waves-j55"} == {"export", "check", "verify"}
    assert_no_temporaries(out)


def test_rich_display(batch: Path, tmp_path: Path) -> None:
    import io

    from rich.console import Console

    from saucerfab.batch.report import RichDisplay, print_table

    csv = batch.parent / "rich.csv"
    csv.write_text(
        "id,design,printer,cup_diameter_mm,export_options\n"
        "waves-j55,designs/waves,j55,80,texture_px=64\n"
        "gone,designs/none,j55,80,\n"
    )
    # there, so the manifest loads (issue 42), but no design.json: the job fails when it runs
    (batch.parent / "designs" / "none").mkdir(exist_ok=True)
    buf = io.StringIO()
    console = Console(file=buf, force_terminal=True, color_system=None, width=200)
    result = run_batch(csv, tmp_path / "out", workers=0, display=RichDisplay(console))
    print_table(result.outcomes, console)
    text = buf.getvalue()
    assert "waves-j55: ok check printable" in text  # a line per finished job
    assert "gone: failed (inputs: 'designs/none' is not a design folder (no design.json)" in text
    assert "2/2" in text  # the overall progress bar
    assert "2 jobs: 1 ok, 1 failed" in text  # the final table's summary


def test_local_dask_cluster_same_outputs(batch: Path, reference: tuple[Path, object], tmp_path: Path) -> None:
    from distributed import LocalCluster

    out = tmp_path / "out"
    rec = Recorder()
    with LocalCluster(
        n_workers=1, threads_per_worker=2, processes=True, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        result = run_batch(batch, out, scheduler=cluster.scheduler_address, display=rec)
        worker_pids = set(cluster.scheduler_info["workers"].keys())
    assert worker_pids
    assert result.exit_code == 1
    assert result.engine.startswith("Dask cluster tcp://127.0.0.1:")
    assert result.outcome(BAD_JOB).status == "failed" and result.outcome(BAD_JOB).stage == "design"
    assert all(result.outcome(j).status == "ok" for j in GOOD_JOBS)
    assert str(os.getpid()) not in {result.outcome(j).worker.split(":")[1] for j in ALL_JOBS}
    assert_same_files(job_files(out), job_files(reference[0]))
    assert (RAW_JOB, "design") in rec.stages  # stage events travel as Dask worker events
    # rerun through the cluster from the command line: everything complete is reused
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        code = main(["batch", str(batch), "--out", str(out), "--scheduler", cluster.scheduler_address, "--quiet"])
    assert code == 1  # the broken upload, run again
    report = json.loads((out / JSON_NAME).read_text())
    assert {j["id"] for j in report["jobs"] if j["reused"]} == set(GOOD_JOBS)
    assert report["engine"].startswith("Dask cluster")


def test_unreachable_scheduler_is_a_clear_error(batch: Path, tmp_path: Path) -> None:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    from saucerfab.batch.executors import DaskEngine

    with pytest.raises(ConfigError, match="cannot reach the Dask scheduler"):
        DaskEngine(f"tcp://127.0.0.1:{port}", connect_timeout=1)
    with pytest.raises(ConfigError, match="tcp://HOST:PORT"):
        DaskEngine("127.0.0.1:8786")


def test_kill_driver_and_workers_then_resume(batch: Path, reference: tuple[Path, object], tmp_path: Path) -> None:
    """kill -9 the driver mid-run after a job finished; its workers go too; a rerun
    reuses every finished job and completes the rest, with the reference's bytes."""
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "saucerfab", "batch", str(batch), "--out", str(out), "--workers", "1"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not any((out / j / MARKER).is_file() for j in ALL_JOBS):
            assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
            assert time.monotonic() < deadline, "no job finished in time"
            time.sleep(0.01)
        children = psutil.Process(proc.pid).children(recursive=True)
        os.kill(proc.pid, signal.SIGKILL)  # the driver, mid-run
        proc.wait(timeout=10)
        # its pool workers notice and leave on their own
        _, alive = psutil.wait_procs(children, timeout=15)
        assert not alive, f"worker processes outlived the killed driver: {alive}"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # anything left in its session
        except ProcessLookupError:
            pass
    finished = {j for j in ALL_JOBS if (m := read_marker(out / j)) and m["complete"]}
    assert finished, "at least one job finished before the kill"
    assert len(finished) < len(ALL_JOBS) - 1, "the kill came after the batch was done; not mid-run"
    # what the kill left: complete job folders only, plus hidden temporaries
    for p in out.iterdir():
        if p.name.startswith("."):
            assert p.name in (LOCK_NAME, ".batch-tmp") or p.name.endswith((".part", ".old")), p
        elif p.is_dir():
            m = read_marker(p)
            assert m is not None, f"{p} has no completion marker"
            if m["complete"]:
                assert completed(out, p.name, m["key"]) is not None
        else:
            assert p.name in (JSON_NAME, HTML_NAME), p
            if p.name == JSON_NAME:
                assert json.loads(p.read_text())["state"] == "running"

    resumed = run_batch(batch, out, workers=1)
    reused = {j for j in ALL_JOBS if resumed.outcome(j).reused}
    assert reused == finished - {BAD_JOB}
    assert all(resumed.outcome(j).status == "ok" for j in GOOD_JOBS)
    assert_same_files(job_files(out), job_files(reference[0]))
    assert_no_temporaries(out)


def test_interrupt_keeps_finished_jobs(batch: Path, reference: tuple[Path, object], tmp_path: Path) -> None:
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it): exit 130,
    the report says interrupted, finished jobs are kept and reused."""
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "saucerfab", "batch", str(batch), "--out", str(out), "--workers", "2"],
        # A shell starts background commands with SIGINT ignored, and Python
        # keeps an inherited SIG_IGN: when the suite runs as `... &` the batch
        # would ignore the signal, finish, and exit 1. Ctrl-C in a terminal
        # reaches a foreground process with the default action; give it that.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not any((out / j / MARKER).is_file() for j in ALL_JOBS):
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.01)
        os.killpg(proc.pid, signal.SIGINT)
        # under a loaded CI machine a worker mid-job (now with its verify stage) can take well over 30 s to stop
        code = proc.wait(timeout=150)
        err = proc.stderr.read().decode() if proc.stderr else ""
        assert code == 130, err
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert "run the same command again" in err, err
    report = json.loads((out / JSON_NAME).read_text())
    assert report["state"] == "interrupted"
    assert_no_temporaries(out)
    finished = {j for j in ALL_JOBS if (m := read_marker(out / j)) and m["complete"]}
    resumed = run_batch(batch, out, workers=0)
    assert {j for j in ALL_JOBS if resumed.outcome(j).reused} == finished
    assert_same_files(job_files(out), job_files(reference[0]))


def test_pool_worker_killed_mid_job_is_retried(batch: Path, reference: tuple[Path, object], tmp_path: Path) -> None:
    out = tmp_path / "out"
    box: dict[str, object] = {}
    quick = batch.parent / "design-jobs.toml"  # the design-folder jobs only
    quick.write_text(MANIFEST.split("\n# -- raw inputs")[0])
    assert len(load_manifest(quick).jobs) == len(DESIGN_JOBS)
    t = threading.Thread(target=lambda: box.update(result=run_batch(quick, out, workers=1)))
    me = psutil.Process()
    t.start()
    killed = None
    deadline = time.monotonic() + 60
    while killed is None and time.monotonic() < deadline and t.is_alive():
        for child in me.children(recursive=True):
            try:
                if "spawn_main" in " ".join(child.cmdline()) and child.cpu_percent(0.05) > 0:
                    child.kill()
                    killed = child.pid
                    break
            except psutil.Error:
                continue
        time.sleep(0.02)
    t.join(180)
    assert killed is not None, "no pool worker to kill"
    result = box["result"]
    assert all(result.outcome(j).status == "ok" for j in DESIGN_JOBS)  # type: ignore[attr-defined]
    assert max(result.outcome(j).attempts for j in DESIGN_JOBS) == 2  # type: ignore[attr-defined]
    ref = {k: v for k, v in job_files(reference[0]).items() if k.split("/")[0] in DESIGN_JOBS}
    assert_same_files(job_files(out), ref)


def test_cli(batch: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    # only the fast jobs, as CSV
    csv = batch.parent / "two.csv"
    csv.write_text(
        "id,design,printer,cup_diameter_mm,formats,export_options\n"
        "waves-j55,designs/waves,j55,80,3mf,texture_px=64\n"
        "ripples-mimaki,designs/ripples,mimaki_3duj553,80,obj,texture_px=64; obj_zip=true\n"
    )
    assert main(["batch", str(csv), "--out", str(out), "--workers", "0", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["batch", str(csv), "--out", str(out), "--dry-run"]) == 0
    text = capsys.readouterr().out
    assert "waves-j55" in text and "complete, would be reused" in text
    assert main(["batch", str(csv), "--out", str(out), "--workers", "0", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["summary"]["reused"] == 2 and report["summary"]["ok"] == 2
    assert main(["batch", str(csv), "--out", str(out), "--workers", "0"]) == 0
    assert "waves-j55" in capsys.readouterr().out  # the table
    # a manifest error: exit 2 and a message, nothing run
    bad = batch.parent / "bad.toml"
    bad.write_text('[[job]]\nid = "x"\nprinter = "j55"\ncup_diameter_mm = 80\ndesign = "../elsewhere"\n')
    assert main(["batch", str(bad), "--out", str(tmp_path / "o2"), "--workers", "0"]) == 2
    err = capsys.readouterr().err
    assert "outside the manifest's folder" in err
    assert not (tmp_path / "o2").exists()


def test_missing_input_fails_that_job_only(tmp_path: Path) -> None:
    manifest = make_batch(
        tmp_path / "b",
        """
[defaults]
printer = "j55"
cup_diameter_mm = 80
export_options = { texture_px = 64 }

[[job]]
id = "fine"
design = "designs/waves"

[[job]]
id = "gone"
design = "designs/missing"

[[job]]
id = "too-big"
design = "designs/ripples"
cup_diameter_mm = 2000
""",
    )
    # there, so the manifest loads (a missing one is refused at load, issue 42), but empty:
    # the job fails when it runs, on its own
    (tmp_path / "b" / "designs" / "missing").mkdir()
    result = run_batch(manifest, tmp_path / "out", workers=0)
    assert result.outcome("fine").status == "ok"
    gone = result.outcome("gone")
    assert gone.status == "failed" and gone.stage == "inputs" and "not a design folder" in gone.reason
    big = result.outcome("too-big")
    assert big.status == "failed" and big.stage == "export" and "build volume" in big.reason
    assert result.exit_code == 1


def test_one_batch_per_output_folder_and_stale_temporaries(batch: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / ".a-j55.x1.part").mkdir()
    (out / ".a-j55.x1.part" / "half.3mf").write_bytes(b"half")
    (out / ".batch-report.json.x.part").write_bytes(b"{")
    (out / "keep.txt").write_text("not ours")
    with _locked(out):
        with pytest.raises(ConfigError, match="another saucerfab batch is writing"):
            run_batch(batch, out, workers=0)
    csv = batch.parent / "one.csv"
    csv.write_text("id,design,printer,cup_diameter_mm,export_options\nwaves-j55,designs/waves,j55,80,texture_px=64\n")
    assert run_batch(csv, out, workers=0).exit_code == 0
    assert_no_temporaries(out)
    assert (out / "keep.txt").read_text() == "not ours"


def test_unprintable_result_is_a_failed_job(tmp_path: Path) -> None:
    """A printer (a profile file beside the manifest) whose minimum wall the part
    cannot meet: the job fails with the reason, the other job is fine."""
    folder = tmp_path / "b"
    manifest = make_batch(
        folder,
        """
[defaults]
cup_diameter_mm = 80
export_options = { texture_px = 64 }

[[job]]
id = "thin"
design = "designs/waves"
printer = "printers/fussy.toml"

[[job]]
id = "fine"
design = "designs/waves"
printer = "j55"
""",
    )
    (folder / "printers").mkdir()
    profile = (ROOT / "printers" / "j55.toml").read_text()
    profile = profile.replace("min_wall_mm = 1.0", "min_wall_mm = 8.0").replace('thin_policy = "warn"', 'thin_policy = "refuse"')
    assert "min_wall_mm = 8.0" in profile and 'thin_policy = "refuse"' in profile
    (folder / "printers" / "fussy.toml").write_text(profile)
    out = tmp_path / "out"
    result = run_batch(manifest, out, workers=0)
    assert result.outcome("fine").status == "ok"
    thin = result.outcome("thin")
    assert thin.status == "failed" and thin.stage in ("export", "check")
    assert "thin" in thin.reason.lower(), thin.reason
    assert result.exit_code == 1
    marker = read_marker(out / "thin")
    if thin.stage == "check":  # complete outputs, kept for inspection, not run again
        assert marker["complete"] and thin.verdict == "not printable"
        assert run_batch(manifest, out, workers=0).outcome("thin").reused
    else:
        assert not marker["complete"]
    # the profile's values are part of the job key: with the J55's, the job runs again and passes
    (folder / "printers" / "fussy.toml").write_text((ROOT / "printers" / "j55.toml").read_text())
    again = run_batch(manifest, out, workers=0)
    assert not again.outcome("thin").reused and again.outcome("thin").status == "ok"
    assert again.outcome("fine").reused
