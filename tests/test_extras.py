"""Installs sized to the user (issue 41): the pip extras, and the commands that name a missing one.

* :data:`saucerfab.extras.EXTRAS` and pyproject.toml's optional dependencies
  list the same names, and the base install holds none of them;
* a command whose extra is missing exits 2 with the extra and its ``pip
  install`` line, before any work (in-process, with
  :func:`saucerfab.extras.installed` answering "no" for the extra's modules);
* ``saucerfab check`` and ``--version`` run with every extra's modules
  unimportable (a subprocess with an import blocker: this process may
  already hold torch and numba), and the checker's fast paths give the
  same reports without numba as with it.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import fixtures_check as fx
import saucerfab.extras as extras
from saucerfab.cli import main

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
EVERY_EXTRA_MODULE = sorted({m for mods in extras.EXTRAS.values() for m in mods})
DESIGN = ROOT / "samples" / "batch" / "designs" / "bowl"  # a design folder that ships with the repository


def _name(requirement: str) -> str:
    """A requirement's distribution name, lower case (``"numba>=0.59"`` -> ``"numba"``)."""
    match = re.match(r"[A-Za-z0-9._-]+", requirement)
    assert match, requirement
    return match.group(0).lower()


def _self_extras(requirement: str) -> set[str] | None:
    """The extras of a ``saucerfab[...]`` requirement (an extra made of others), or None for another package."""
    match = re.fullmatch(r"saucerfab\[([^\]]*)\]", requirement.replace(" ", ""))
    return set(match.group(1).split(",")) if match else None


# --------------------------------------------------------------------------- the table and pyproject


def test_extras_table_matches_pyproject() -> None:
    optional = PYPROJECT["project"]["optional-dependencies"]
    for extra, modules in extras.EXTRAS.items():
        assert extra in optional, f"pyproject.toml has no [{extra}] extra; saucerfab/extras.py names it"
        names = {_name(r) for r in optional[extra]}
        assert names == set(modules), f"[{extra}]: pyproject.toml lists {sorted(names)}, extras.py {sorted(modules)}"
    assert [_self_extras(r) for r in optional["all"]] == [set(extras.ALL_EXTRAS)], optional["all"]
    assert set(extras.ALL_EXTRAS) <= set(extras.EXTRAS)


def test_base_install_holds_no_extra_and_bounds_agree() -> None:
    core = {_name(r) for r in PYPROJECT["project"]["dependencies"]}
    assert not core & set(EVERY_EXTRA_MODULE), f"in the base install and an extra: {sorted(core & set(EVERY_EXTRA_MODULE))}"
    assert {"numpy", "lib3mf", "dracopy", "defusedxml", "rich", "pillow"} <= core  # what saucerfab check reads with
    # a package in two extras (scipy: design and verify) has one version bound
    bounds: dict[str, set[str]] = {}
    for reqs in [PYPROJECT["project"]["dependencies"], *PYPROJECT["project"]["optional-dependencies"].values()]:
        for r in reqs:
            if _self_extras(r) is None:
                bounds.setdefault(_name(r), set()).add(r.replace(" ", ""))
    assert {n: b for n, b in bounds.items() if len(b) > 1} == {}


def test_each_module_of_the_table_is_an_importable_name() -> None:
    # `make install` installs every extra: a name that is a distribution but not a module would never be found
    assert [m for m in EVERY_EXTRA_MODULE if not extras.installed(m)] == []
    assert not extras.installed("saucerfab_no_such_module")


# --------------------------------------------------------------------------- the message of a missing extra


@pytest.fixture
def without(monkeypatch: pytest.MonkeyPatch):  # type: ignore[no-untyped-def]
    """``without(*modules)``: :func:`saucerfab.extras.installed` answers False for those modules."""

    def block(*modules: str) -> None:
        real = extras.installed
        monkeypatch.setattr(extras, "installed", lambda m: m not in modules and real(m))

    return block


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(argv)
    return code, capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, blocked, wanted",
    [
        (["design", "--direct", "a.png", "--reflected", "b.png", "-o", "OUT"], ["torch"], "'saucerfab[design]'"),
        (["export", str(DESIGN), "-o", "OUT"], ["xatlas"], "'saucerfab[design]'"),
        (["verify", "OUT"], ["mitsuba"], "'saucerfab[verify]'"),
        (["studio"], ["uvicorn"], "'saucerfab[studio]'"),
        (["batch", str(ROOT / "samples" / "batch" / "manifest.toml"), "-o", "OUT"], ["numba"], "'saucerfab[design]'"),
        (["batch", str(ROOT / "samples" / "batch" / "manifest.toml"), "-o", "OUT", "--scheduler", "tcp://h:1"],
         ["distributed"], "'saucerfab[cluster]'"),
    ],
    ids=["design", "export", "verify", "studio", "batch", "batch-scheduler"],
)
def test_a_command_names_its_missing_extra_before_any_work(
    argv: list[str], blocked: list[str], wanted: str, without, tmp_path: Path,  # type: ignore[no-untyped-def]
    capsys: pytest.CaptureFixture[str],
) -> None:
    without(*blocked)
    out = tmp_path / "out"
    code, err = _run([str(out) if a == "OUT" else a for a in argv], capsys)
    assert code == 2, err
    assert f"pip install {wanted}" in err and f"{', '.join(blocked)} missing" in err, err
    assert "Traceback" not in err
    assert not out.exists(), "the command worked before saying its extra is missing"


@pytest.mark.parametrize("command", ["design", "export"])
def test_the_verify_of_design_and_export_names_its_extra_and_no_verify(
    command: str, without, tmp_path: Path, capsys: pytest.CaptureFixture[str]  # type: ignore[no-untyped-def]
) -> None:
    without("mitsuba")
    args = (["--direct", "a.png", "--reflected", "b.png"] if command == "design" else [str(DESIGN)])
    code, err = _run([command, *args, "-o", str(tmp_path / "out")], capsys)
    assert code == 2 and "pip install 'saucerfab[verify]', or add --no-verify" in err, err
    assert not (tmp_path / "out").exists()


def test_several_missing_extras_in_one_line_each_module_once(without) -> None:  # type: ignore[no-untyped-def]
    without("starlette", "scipy", "mitsuba")
    with pytest.raises(extras.MissingExtraError) as info:
        extras.require("studio", "design", "verify")
    msg = str(info.value)
    assert msg == ("this command needs the 'studio', 'design' and 'verify' extras, which are not installed "
                   "(starlette, scipy, mitsuba missing): pip install 'saucerfab[studio,design,verify]'"), msg
    assert info.value.exit_code == 2
    extras.require("cluster")  # installed: no error


# --------------------------------------------------------------------------- the checker without any extra

BLOCKER = """
import importlib.abc, json, sys
BLOCKED = set(filter(None, sys.argv[1].split(",")))

class Blocker(importlib.abc.MetaPathFinder):  # as if those packages were not installed
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r} (blocked by the test)", name=name)
        return None

sys.meta_path.insert(0, Blocker())
"""

# every fast path of the checker taken on small files: the numba one where numba is importable
CHECK_ALL_PATHS = BLOCKER + """
import saucerfab.check.bvh as bvh, saucerfab.check.readers.obj as obj, saucerfab.check.readers.threemf_blocks as tb
bvh.FAST_FROM_TRIANGLES = obj.FAST_OBJ_BYTES = tb.FAST_3MF_PART_BYTES = tb.FAST_3MF_BLOCK_BYTES = 0
from saucerfab.cli import main
code = main(["check", "--json", *sys.argv[2:]])
print(json.dumps({"code": code, "loaded": sorted(m for m in sys.modules if m.partition(".")[0] in
                  {"numba", "torch", "scipy", "mitsuba", "starlette", "uvicorn", "trimesh", "manifold3d"})}))
"""


def _subprocess(code: str, blocked: list[str], *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", code, ",".join(blocked), *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=300, check=False)


def _reports(stdout: str) -> tuple[list[dict], dict]:
    """The check's JSON reports (times left out) and the last line's exit code and loaded modules."""
    *doc, last = stdout.strip().splitlines()
    files = json.loads("\n".join(doc))["files"]

    def untimed(d):  # type: ignore[no-untyped-def]
        if isinstance(d, dict):
            return {k: untimed(v) for k, v in d.items() if "elapsed" not in k}
        return [untimed(x) for x in d] if isinstance(d, list) else d

    return untimed(files), json.loads(last)


def test_check_without_any_extra_reads_every_path_as_with_numba(tmp_path: Path) -> None:
    V, F, uv = fx.saucer_solid(n=10)  # numpy-only writers: no trimesh
    files = [fx.write_stl(tmp_path / "s.stl", V, F), fx.write_obj(tmp_path / "s.obj", V, F),
             fx.write_3mf(tmp_path / "s.3mf", V, F, uv=uv, texture=fx.png_bytes(16, 16)),
             ROOT / "tests" / "data" / "gltf-compressed" / "meshopt-khr.glb"]  # meshopt: numba kernels, or Python
    bare = _subprocess(CHECK_ALL_PATHS, [*EVERY_EXTRA_MODULE, "trimesh", "llvmlite"], *map(str, files))
    assert bare.returncode == 0, bare.stderr
    got, info = _reports(bare.stdout)
    assert info == {"code": 0, "loaded": []}, info
    assert [r["verdict"] for r in got] == ["printable"] * len(files), [(r["path"], r["reason"]) for r in got]
    full = _subprocess(CHECK_ALL_PATHS, [], *map(str, files))
    assert full.returncode == 0, full.stderr
    want, info = _reports(full.stdout)
    assert "numba" in info["loaded"], "the full install did not take the numba paths: the comparison is void"
    assert got == want


def test_version_without_torch() -> None:
    done = _subprocess(BLOCKER + "from saucerfab.cli import main\nmain(['--version'])", ["torch"])
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("saucerfab ") and lines[1].startswith("Python 3.")
    assert lines[2].startswith("torch not installed") and "pip install 'saucerfab[design]'" in lines[2], lines
