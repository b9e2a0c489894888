"""Conformance suites for ``saucerfab check``, and the formats' own reference readers' verdicts.

Used by ``tests/check/test_conformance.py`` (CI) and ``benchmarks/bench_conformance.py``
(the agreement table in ``saucerfab/check/README.md``), so that the test and
the table count the same way.

Suites (files nobody on this project wrote, vendored under
``tests/data/conformance/`` with their licences and provenance):

* ``3mf-mustfail`` / ``3mf-mustpass``: the 3MF Consortium's validation files,
  labelled by their name (``MUSTFAIL_...``, ``MUSTPASS_...``);
* ``3mf-examples``: the Consortium's example files (valid 3MF);
* ``gltf-validator``: the Khronos glTF-Validator's test assets, labelled by
  the validator itself (no errors: valid);
* ``gltf-compressed``: Draco / meshopt / quantized files made by independent
  encoders from a source model made here (``tests/data/gltf-compressed/``).

Reference readers: **lib3mf** (the 3MF Consortium's reader) in strict mode,
run in this process (it is the reference, not the thing under test), and
the **Khronos glTF-Validator** (npm, installed by ``.ci/install-tools`` into
``tools/node``), run once over all files of a suite by one node process.

Agreement, per file:

* a file its suite calls invalid (must-fail) *agrees* when check does not
  call it printable;
* a file its suite calls valid *agrees* when check reads it (printable, or
  not printable for its geometry: a valid file can still be a bad print);
  a valid file holding no triangles at all is counted apart
  (``no_triangles`` is the right answer for a material-only test asset);
* a glTF file the validator calls invalid has no expectation (its errors are
  mostly about animation, skins and cameras, which printing never reads):
  the table only counts what check says.
"""

from __future__ import annotations

import json
import os
import subprocess
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "conformance"
COMPRESSED = ROOT / "tests" / "data" / "gltf-compressed"
GLTF_VALIDATOR = ROOT / "tools" / "node" / "node_modules" / "gltf-validator"

Label = Literal["valid", "invalid", "unknown"]

#: suite name -> (folder, file patterns); every suite's files sorted by path
SUITES: dict[str, tuple[Path, tuple[str, ...]]] = {
    "3mf-mustfail": (DATA / "3mf-samples" / "MUSTFAIL", ("*.3mf",)),
    "3mf-mustpass": (DATA / "3mf-samples" / "MUSTPASS", ("*.3mf",)),
    "3mf-examples": (DATA / "3mf-samples" / "examples", ("*.3mf",)),
    "gltf-validator": (DATA / "gltf-validator" / "test", ("**/*.gltf", "**/*.glb")),
    "gltf-compressed": (COMPRESSED, ("*.gltf", "*.glb")),
}


@dataclass
class Row:
    """One file of a suite: its label, the reference reader's verdict and check's.

    Attributes:
        suite: a key of :data:`SUITES`.
        path: the file.
        label: what the suite says it is (``unknown``: the suite has no
            label for it, and the reference reader's verdict stands in).
        reference: the reference reader's verdict: ``reads`` or ``rejects``.
        reference_message: its first error, if it rejects.
        verdict: check's verdict (``printable`` / ``not printable`` / ``unreadable``).
        codes: check's error codes (unreadable codes included).
        reason: check's one-line reason.
        elapsed_s: check's own time on the file.
    """

    suite: str
    path: Path
    label: Label
    reference: str
    reference_message: str
    verdict: str = ""
    codes: list[str] = field(default_factory=list)
    reason: str = ""
    elapsed_s: float = 0.0

    @property
    def name(self) -> str:
        return self.path.relative_to(SUITES[self.suite][0]).as_posix()

    @property
    def expected(self) -> Label:
        """The label, or the reference reader's verdict for a glTF file the suite leaves to the validator."""
        if self.label != "unknown":
            return self.label
        return "valid" if self.reference == "reads" else "invalid"

    @property
    def no_triangles(self) -> bool:
        return self.codes == ["no_triangles"]

    @property
    def outcome(self) -> str:
        """``agree``, ``disagree``, ``empty`` (a valid file with no triangles) or ``info`` (no expectation)."""
        exp = self.expected
        if self.suite.startswith("gltf") and exp == "invalid":
            return "info"
        if exp == "invalid":
            return "agree" if self.verdict != "printable" else "disagree"
        if self.verdict != "unreadable":
            return "agree"
        return "empty" if self.no_triangles else "disagree"


def suite_files(suite: str) -> list[Path]:
    folder, patterns = SUITES[suite]
    files: set[Path] = set()
    for pat in patterns:
        files.update(p for p in folder.glob(pat) if p.is_file())
    return sorted(files)


def label_of(suite: str, path: Path) -> Label:
    if suite == "3mf-mustfail":
        return "invalid"
    if suite in ("3mf-mustpass", "3mf-examples", "gltf-compressed"):
        return "valid"
    return "unknown"


# -- reference readers ----------------------------------------------------------------------------


def lib3mf_strict(path: Path) -> tuple[str, str]:
    """lib3mf's verdict on a 3MF in strict mode (warnings count as errors): (``reads``/``rejects``, message)."""
    import lib3mf

    wrapper = lib3mf.get_wrapper()
    model = wrapper.CreateModel()
    reader = model.QueryReader("3mf")
    reader.SetStrictModeActive(True)
    try:
        reader.ReadFromFile(os.fspath(path))
    except Exception as exc:
        return "rejects", str(exc).splitlines()[0][:200]
    n = reader.GetWarningCount()
    if n:
        return "rejects", "; ".join(reader.GetWarning(i)[1] for i in range(min(n, 3)))[:200]
    return "reads", ""


_NODE_SCRIPT = r"""
const fs = require('fs'), path = require('path');
const v = require(process.argv[1]);
const files = JSON.parse(fs.readFileSync(0, 'utf8'));
(async () => {
  const out = {};
  for (const p of files) {
    try {
      const r = await v.validateBytes(new Uint8Array(fs.readFileSync(p)), {
        uri: path.basename(p), maxIssues: 20,
        externalResourceFunction: (uri) => new Promise((res, rej) => {
          fs.readFile(path.resolve(path.dirname(p), decodeURIComponent(uri)),
                      (e, d) => e ? rej(String(e)) : res(new Uint8Array(d)));
        }),
      });
      const errs = r.issues.messages.filter(m => m.severity === 0).map(m => m.code + ': ' + m.message);
      out[p] = [r.issues.numErrors, errs.slice(0, 3).join('; ')];
    } catch (e) { out[p] = [1, 'validator failed: ' + String(e)]; }
  }
  process.stdout.write(JSON.stringify(out));
})();
"""


def gltf_validator(paths: Iterable[Path]) -> dict[Path, tuple[str, str]]:
    """The Khronos glTF-Validator's verdict on each glTF/GLB: {path: (``reads``/``rejects``, first errors)}."""
    paths = list(paths)
    if not (GLTF_VALIDATOR / "package.json").is_file():
        raise FileNotFoundError(f"gltf-validator is not installed in {GLTF_VALIDATOR}: run bash .ci/install-tools")
    proc = subprocess.run(["node", "-e", _NODE_SCRIPT, str(GLTF_VALIDATOR)],
                          input=json.dumps([os.fspath(p) for p in paths]), capture_output=True, text=True,
                          timeout=600, check=True)
    raw = json.loads(proc.stdout)
    return {p: ("reads" if raw[os.fspath(p)][0] == 0 else "rejects", raw[os.fspath(p)][1]) for p in paths}


# -- running a suite ------------------------------------------------------------------------------


def run_suite(suite: str) -> list[Row]:
    """Every file of ``suite`` through the reference reader and ``saucerfab check`` (default limits, no printer)."""
    from saucerfab.check import check_mesh

    files = suite_files(suite)
    if suite.startswith("3mf"):
        refs = {p: lib3mf_strict(p) for p in files}
    else:
        refs = gltf_validator(files)
    rows = []
    for p in files:
        ref, msg = refs[p]
        row = Row(suite, p, label_of(suite, p), ref, msg)
        t0 = time.perf_counter()
        r = check_mesh(p)
        row.elapsed_s = time.perf_counter() - t0
        row.verdict = r.verdict
        row.codes = sorted({f.code for f in r.findings if f.severity == "error"})
        row.reason = r.reason()
        rows.append(row)
    return rows
