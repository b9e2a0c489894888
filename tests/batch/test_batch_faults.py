"""Batch faults (issue 16): manifests that used to jam or crash the batch, and a
Dask worker killed mid-batch.

* a job id naming a file the batch writes (``batch-report.json``) is refused;
* a job id with a trailing newline is refused (the id pattern is a full match);
* every design option value ``saucerfab design`` refuses is refused when the
  manifest loads (``resolution = 1000000``...), with the design's own rules;
* a manifest nesting arrays thousands deep is exit 2 with a message, not a
  RecursionError traceback;
* a Dask worker process killed mid-batch costs no job (its jobs run again),
  and Dask's own log lines stay off the terminal while a batch runs;
* a raw-input job gives byte-identical files run to run (what
  ``samples/batch/README.md`` says).
"""

from __future__ import annotations

import logging
import os
import shutil
import signal
import threading
import time
from pathlib import Path

import pytest

from saucerfab.batch import load_manifest, run_batch, run_job
from saucerfab.batch.manifest import parse_options_cell
from saucerfab.cli import main
from saucerfab.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "samples" / "batch"

HEAD = '[defaults]\nprinter = "j55"\ncup_diameter_mm = 80\n\n'


def _manifest(folder: Path, text: str, name: str = "m.toml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    # the inputs the jobs below name: a manifest's files must exist when it loads (issue 42)
    (folder / "d").mkdir(exist_ok=True)
    for image in ("a.png", "b.png"):
        (folder / image).write_bytes(b"")
    p = folder / name
    p.write_text(text, encoding="utf-8")
    return p


def _raw_job(options: str, scene: str = "") -> str:
    """A raw-input job (design + export + check) with ``design_options = { options }``."""
    return (
        HEAD
        + '[[job]]\nid = "raw"\ndirect = "a.png"\nreflected = "b.png"\n'
        + (f'scene = "{scene}"\n' if scene else "")
        + f"design_options = {{ {options} }}\n"
    )


# --------------------------------------------------------------------------- job ids


@pytest.mark.parametrize(
    "job_id", ["batch-report.json", "batch-report.html", "Batch-Report.JSON", "BATCH-REPORT.html"]
)
def test_a_job_id_naming_a_batch_file_is_refused(tmp_path: Path, job_id: str) -> None:
    m = _manifest(tmp_path, HEAD + f'[[job]]\nid = "{job_id}"\ndesign = "d"\n')
    with pytest.raises(ConfigError, match="the name of a file the batch writes") as exc:
        load_manifest(m)
    assert repr(job_id) in str(exc.value) and "another id" in str(exc.value)
    # the command line: exit 2, nothing written
    assert main(["batch", str(m), "--out", str(tmp_path / "out"), "--workers", "0", "--quiet"]) == 2
    assert not (tmp_path / "out").exists()


def test_ids_like_the_reports_but_not_them_are_fine(tmp_path: Path) -> None:
    text = HEAD + "".join(
        f'[[job]]\nid = "{i}"\ndesign = "d"\n\n' for i in ("batch-report", "batch-report.json.1", "report.json")
    )
    assert [j.id for j in load_manifest(_manifest(tmp_path, text)).jobs] == [
        "batch-report", "batch-report.json.1", "report.json"
    ]


@pytest.mark.parametrize("job_id", ["CON", "nul", "Aux.txt", "COM1", "lpt9.tar.gz", "job."])
def test_a_job_id_windows_cannot_name_is_refused_everywhere(tmp_path: Path, job_id: str) -> None:
    m = _manifest(tmp_path, HEAD + f'[[job]]\nid = "{job_id}"\ndesign = "d"\n')
    with pytest.raises(ConfigError, match="cannot name a folder on Windows"):
        load_manifest(m)


def test_ids_that_only_start_like_a_device_are_fine(tmp_path: Path) -> None:
    text = HEAD + "".join(f'[[job]]\nid = "{i}"\ndesign = "d"\n\n' for i in ("console", "COM10", "nullable.1"))
    assert [j.id for j in load_manifest(_manifest(tmp_path, text)).jobs] == ["console", "COM10", "nullable.1"]


def test_a_printer_profile_nested_too_deeply_is_a_config_error(tmp_path: Path) -> None:
    from saucerfab.model.profiles import load_profile

    p = tmp_path / "deep.toml"
    p.write_text('name = "x"\nnotes = ' + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(ConfigError, match="nests arrays or tables too deeply"):
        load_profile(p)


def test_a_job_id_with_a_trailing_newline_is_refused(tmp_path: Path) -> None:
    m = _manifest(tmp_path, HEAD + '[[job]]\nid = "job\\n"\ndesign = "d"\n')
    with pytest.raises(ConfigError, match="not a valid name"):
        load_manifest(m)


# --------------------------------------------------------------------------- design option values


@pytest.mark.parametrize(
    "options, words",
    [
        ("resolution = 1000000", ["resolution", "1024", "1000000"]),
        ("resolution = 2", ["resolution", "[4, 1024]"]),
        ("image_size = 100000", ["image_size", "4096"]),
        ('resolution = "40"', ["resolution must be a whole number", "'40'"]),
        ("resolution = 40.5", ["resolution must be a whole number"]),
        ('seed = "seven"', ["seed must be a whole number"]),
        ("max_iters = true", ["max_iters must be a whole number"]),
        ('height_scale = "big"', ["height_scale must be a number"]),
        ("height_scale = -1.0", ["height_scale must be a positive number"]),
        ("height_scale = nan", ["height_scale must be a positive number"]),
        ("record_times = 1", ["record_times must be true or false"]),
        ('ablation = "sparse_only", w_large = 0.5', ["--w-large is not used by --ablation sparse_only"]),
    ],
)
def test_bad_design_option_values_are_refused_when_the_manifest_loads(
    tmp_path: Path, options: str, words: list[str]
) -> None:
    m = _manifest(tmp_path, _raw_job(options))
    with pytest.raises(ConfigError) as exc:
        load_manifest(m)
    text = str(exc.value)
    assert "nothing was run" in text and "design_options" in text
    for w in words:
        assert w in text, (w, text)


def test_the_scene_ranges_are_checked_for_a_job_with_a_scene_file_too(tmp_path: Path) -> None:
    (tmp_path / "s").mkdir(parents=True)
    shutil.copy(SAMPLE / "scenes" / "small_cup.toml", tmp_path / "s" / "small.toml")
    with pytest.raises(ConfigError, match=r"resolution must be an integer in \[4, 1024\]"):
        load_manifest(_manifest(tmp_path, _raw_job("resolution = 1000000", scene="s/small.toml")))
    # good values (the sample's) load, with a scene file or a preset
    for scene in ("s/small.toml", ""):
        m = load_manifest(_manifest(tmp_path, _raw_job("resolution = 24, image_size = 32, height_scale = 1", scene)))
        assert m.jobs[0].design_options == {"resolution": 24, "image_size": 32, "height_scale": 1}


def test_bad_values_in_a_csv_manifest_are_refused_too(tmp_path: Path) -> None:
    m = _manifest(
        tmp_path,
        "id,direct,reflected,printer,cup_diameter_mm,design_options\nraw,a.png,b.png,j55,80,resolution=1000000\n",
        "m.csv",
    )
    with pytest.raises(ConfigError, match="resolution must be an integer"):
        load_manifest(m)


# --------------------------------------------------------------------------- nesting


def test_a_deeply_nested_toml_manifest_is_exit_2_with_a_message(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    deep = "[" * 5000 + "]" * 5000
    for name, text in (
        ("top.toml", f"x = {deep}\n"),
        ("job.toml", HEAD + f'[[job]]\nid = "a"\ndesign = "d"\nexport_options = {{ name = {deep} }}\n'),
    ):
        m = _manifest(tmp_path, text, name)
        code = main(["batch", str(m), "--out", str(tmp_path / "out"), "--dry-run"])
        err = capsys.readouterr().err
        assert code == 2, err
        assert "nests arrays or tables too deeply" in err and "Traceback" not in err
    # deep enough to matter, shallow enough for the parser: refused by the depth check
    m = _manifest(tmp_path, HEAD + '[[job]]\nid = "a"\ndesign = "d"\nexport_options = { name = ' + "[" * 100 + "]" * 100 + " }\n")
    with pytest.raises(ConfigError, match="levels deep"):
        load_manifest(m)


def test_a_deeply_nested_csv_cell_is_a_clear_error() -> None:
    with pytest.raises(ConfigError, match="too deeply"):
        parse_options_cell("name=" + "[" * 5000 + "]" * 5000, "m.csv row 1 export_options")
    with pytest.raises(ConfigError, match="levels deep"):
        parse_options_cell("name=" + "[" * 100 + "]" * 100, "m.csv row 1 export_options")


# --------------------------------------------------------------------------- Dask


def _design_jobs(folder: Path, n: int) -> Path:
    """``n`` design-folder jobs (export + check of the sample's small designs, 64 px textures)."""
    shutil.copytree(SAMPLE / "designs", folder / "designs")
    names = ["waves", "ripples", "bowl"]
    jobs = "".join(f'[[job]]\nid = "j{i}"\ndesign = "designs/{names[i % 3]}"\n\n' for i in range(n))
    return _manifest(folder, HEAD + "export_options = { texture_px = 64 }\n\n" + jobs)


def test_a_dask_worker_killed_mid_batch_costs_no_job(tmp_path: Path) -> None:
    """Kill -9 one worker process of a two-worker LocalCluster while it runs a job:
    every job ends ok; the killed jobs ran twice (the local pool's retry policy)."""
    from distributed import LocalCluster

    manifest = _design_jobs(tmp_path / "b", 4)
    out = tmp_path / "out"
    box: dict[str, object] = {}
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as cluster:

        def batch() -> None:
            try:
                box["result"] = run_batch(manifest, out, scheduler=cluster.scheduler_address)
            except BaseException as exc:  # noqa: BLE001 - reported by the assertions below
                box["error"] = exc

        t = threading.Thread(target=batch)
        t.start()
        killed = None
        deadline = time.monotonic() + 120
        while killed is None and t.is_alive() and time.monotonic() < deadline:
            # the scheduler runs in this process: ask it which worker is running a job
            for ws in list(cluster.scheduler.workers.values()):
                if any(str(ts.key).startswith("saucerfab-job-") for ts in ws.processing) and ws.pid:
                    os.kill(ws.pid, signal.SIGKILL)
                    killed = ws.pid
                    break
            time.sleep(0.02)
        t.join(300)
    assert not t.is_alive(), "the batch did not finish"
    assert "error" not in box, box.get("error")
    assert killed is not None, "no worker was running a job to kill"
    result = box["result"]
    outcomes = {o.id: o for o in result.outcomes}  # type: ignore[attr-defined]
    assert {j: o.status for j, o in outcomes.items()} == {f"j{i}": "ok" for i in range(4)}, {
        j: o.reason for j, o in outcomes.items()
    }
    assert max(o.attempts for o in outcomes.values()) == 2  # the killed worker's job ran again
    assert result.exit_code == 0  # type: ignore[attr-defined]


def test_dask_logs_are_kept_off_the_terminal_while_a_batch_runs(
    capfd: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    """Dask's loggers print to stderr (a traceback, once, when the scheduler died
    under a batch): while a Dask engine is open they are silent, and as they
    were once it closes. (Under pytest Dask leaves its records to the root
    logger, which caplog holds; on a terminal its own handler prints them:
    a record dropped where it is made reaches neither.)"""
    from distributed import LocalCluster

    from saucerfab.batch.executors import DaskEngine

    names = ("distributed", "distributed.client", "tornado.application")
    before = {n: logging.getLogger(n).level for n in names}
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        engine = DaskEngine(cluster.scheduler_address)
        try:
            capfd.readouterr()
            caplog.clear()
            try:
                raise OSError("Stream is closed")
            except OSError:
                logging.getLogger("distributed.client").exception("Failed to reconnect to scheduler")
                logging.getLogger("distributed.comm.new_child").error("lost the comm")  # made now: silent too
                logging.getLogger("tornado.application").exception("Exception in callback")
            err = capfd.readouterr().err
            records = [r.getMessage() for r in caplog.records if r.name.startswith(("distributed", "tornado"))]
        finally:
            engine.close()
    assert not records, records
    assert "Traceback" not in err and "reconnect" not in err and "lost the comm" not in err, err
    assert {n: logging.getLogger(n).level for n in names} == before


# --------------------------------------------------------------------------- determinism (samples/batch/README.md)


def test_a_raw_input_job_is_byte_identical_run_to_run(tmp_path: Path) -> None:
    """The README says two runs of the same job give the same bytes, design folder
    included (batch designs record no wall-clock times); job.json lists every
    file's sha256, so equal markers mean equal files."""
    folder = tmp_path / "b"
    shutil.copytree(SAMPLE / "images", folder / "images")
    m = load_manifest(
        _manifest(
            folder,
            HEAD
            + "export_options = { texture_px = 64 }\n"
            + '[[job]]\nid = "raw"\ndirect = "images/ring.png"\nreflected = "images/star.png"\n'
            + "design_options = { resolution = 12, image_size = 16, max_iters = 4 }\n",
        )
    )
    runs = []
    for name in ("one", "two"):
        result, reused = run_job(m.job("raw"), m.root, tmp_path / name)
        assert result.status == "ok" and not reused, result.reason
        root = tmp_path / name / "raw"
        runs.append({p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()})
    assert sorted(runs[0]) == sorted(runs[1])
    assert "design/design.json" in runs[0] and "design/energy_log.jsonl" in runs[0]
    assert [k for k in runs[0] if runs[0][k] != runs[1][k]] == []
    readme = (SAMPLE / "README.md").read_text(encoding="utf-8")
    assert "differ between two runs" not in readme  # the README once said three design files did
