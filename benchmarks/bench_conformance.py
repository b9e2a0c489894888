"""Benchmark: ``saucerfab check`` against the formats' conformance files and reference readers (issue 15).

    .venv/bin/python benchmarks/bench_conformance.py [--suite NAME ...] [--readme] [--out FILE]

Runs every vendored suite of ``tests/conformance.py`` (the 3MF Consortium's
must-fail / must-pass / example files with lib3mf strict as the reference;
the Khronos glTF-Validator's test assets and the compressed glTF made by
independent encoders, with the validator as the reference) and prints the
agreement table: per suite the files, how many agree with the suite's label,
which disagree and why, how often the reference reader rejects, and check's
own time per file (median and max, no printer profile). ``--readme``
rewrites the table in ``saucerfab/check/README.md`` between its
``conformance:begin`` / ``conformance:end`` markers; ``--out`` also writes
the rows as JSON. The counting rules are in ``tests/conformance.py``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the suites and reference readers live with the tests
sys.path.insert(0, str(ROOT / "benchmarks"))

import conformance as cf  # noqa: E402 - found through the path above
from bench_check_hostile import machine, uptime  # noqa: E402

from saucerfab.files.fileio import write_text_atomic  # noqa: E402

README = ROOT / "saucerfab" / "check" / "README.md"
BEGIN, END = "<!-- conformance:begin -->", "<!-- conformance:end -->"

#: suite -> (what it is, its reference reader)
ABOUT = {
    "3mf-mustfail": ("3MF Consortium must-fail", "lib3mf strict"),
    "3mf-mustpass": ("3MF Consortium must-pass", "lib3mf strict"),
    "3mf-examples": ("3MF Consortium examples", "lib3mf strict"),
    "gltf-validator": ("glTF-Validator test assets", "glTF-Validator"),
    "gltf-compressed": ("Draco / meshopt / quantized glTF", "glTF-Validator"),
}


def table(rows_by_suite: dict[str, list[cf.Row]]) -> str:
    """The agreement table and the list of disagreements, as Markdown."""
    out = ["| suite | files | label | agree | disagree | no triangles | reference rejects | check s/file median / max |",
           "|---|---:|---|---:|---:|---:|---:|---|"]
    notes: list[str] = []
    for suite, rows in rows_by_suite.items():
        what, ref = ABOUT[suite]
        by = {k: [r for r in rows if r.outcome == k] for k in ("agree", "disagree", "empty", "info")}
        labels = sorted({r.expected for r in rows if r.outcome != "info"})
        times = [r.elapsed_s for r in rows]
        rejects = sum(r.reference == "rejects" for r in rows if r.outcome != "info")
        if by["info"]:  # glTF files the validator calls invalid: no expectation, only what check says
            flagged = sum(r.verdict != "printable" for r in by["info"])
            notes.append(f"- {what}: of the {len(by['info'])} files the validator calls invalid, check flags "
                         f"{flagged} (most are invalid in animation, skin or camera data, which printing never "
                         "reads; these are not counted above)")
        valid = [r for r in rows if r.expected == "valid"]
        out.append(
            f"| {what} | {len(rows) - len(by['info'])} | {'/'.join(x for x in labels if x)} "
            f"| {len(by['agree'])} | {len(by['disagree'])} | {len(by['empty'])} "
            f"| {rejects} ({ref}) | {statistics.median(times):.3f} / {max(times):.3f} |"
        )
        for r in by["disagree"]:
            notes.append(f"- {what}, `{r.name}` ({r.expected}): check says {r.reason}; {ref} "
                         f"{r.reference}{': ' + r.reference_message if r.reference_message else ''}")
        for r in valid:
            if r.outcome == "agree" and r.reference == "rejects":
                notes.append(f"- {what}, `{r.name}` (valid): {ref} rejects it ({r.reference_message}); "
                             f"check reads it: {r.verdict}")
    return "\n".join(out + [""] + (notes or ["- no disagreements"]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--suite", action="append", choices=sorted(cf.SUITES), help="only these suites (repeatable)")
    ap.add_argument("--readme", action="store_true", help="rewrite the table in saucerfab/check/README.md")
    ap.add_argument("--out", type=Path, help="also write the rows as JSON here")
    args = ap.parse_args(argv)
    suites = args.suite or list(cf.SUITES)
    rows = {s: cf.run_suite(s) for s in suites}
    md = table(rows)
    head = f"Measured on {machine()}; {uptime()}. Rerun: `.venv/bin/python benchmarks/bench_conformance.py --readme`."
    print(head + "\n\n" + md)
    if args.out:
        write_text_atomic(args.out, json.dumps(
            [{"suite": r.suite, "file": r.name, "label": r.expected, "reference": r.reference,
              "reference_message": r.reference_message, "verdict": r.verdict, "codes": r.codes,
              "outcome": r.outcome, "elapsed_s": round(r.elapsed_s, 4)} for rs in rows.values() for r in rs],
            indent=1) + "\n")
    if args.readme:
        if args.suite:
            ap.error("--readme rewrites the whole table: run it on every suite (no --suite)")
        text = README.read_text()
        if BEGIN not in text or END not in text:
            print(f"{README} has no {BEGIN} ... {END} markers", file=sys.stderr)
            return 2
        pre, rest = text.split(BEGIN, 1)
        _, post = rest.split(END, 1)
        write_text_atomic(README, pre + BEGIN + "\n" + head + "\n\n" + md + "\n" + END + post)
    return 0


if __name__ == "__main__":
    sys.exit(main())
