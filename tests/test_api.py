"""The public Python API: ``saucerfab.__all__``, loaded lazily, and the README's example run as written."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import saucerfab

ROOT = Path(__file__).resolve().parents[1]


def test_every_public_name_resolves_and_importing_the_package_stays_light() -> None:
    for name in saucerfab.__all__:
        assert getattr(saucerfab, name) is not None, name
    code = "import sys, saucerfab; print(any(m == 'torch' or m.startswith('torch.') for m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"  # import saucerfab loads no torch: `saucerfab check` starts fast


def test_an_unknown_name_is_an_attribute_error() -> None:
    try:
        saucerfab.no_such_function  # noqa: B018
    except AttributeError as exc:
        assert "no_such_function" in str(exc)
    else:
        raise AssertionError("an unknown name resolved")


def test_the_readmes_python_example_runs(tmp_path: Path) -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    section = readme.split("## Python API", 1)[1]
    block = re.search(r"```python\n(.*?)```", section, re.S)
    assert block, "the README's Python API section has no python block"
    code = block.group(1)
    assert len(code.strip().splitlines()) <= 12, "the example is meant to be about ten lines"
    (tmp_path / "samples").symlink_to(ROOT / "samples")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, env=env,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    lines = run.stdout.strip().splitlines()
    assert "('saucer.3mf', 'printable')" in lines[0] and "('saucer.obj', 'printable')" in lines[0], lines
    views = [ln.split() for ln in lines[1:]]
    assert {(v[0], v[1]) for v in views} == {(a, b) for a in ("direct", "reflected") for b in ("design", "left", "right")}
    assert (tmp_path / "out" / "api" / "design" / "design.json").is_file()
