"""``saucerfab check`` against the formats' own conformance files and reference readers (issue 15).

Every vendored file of every suite (``tests/conformance.py``) goes through
``check`` and through the format's reference reader (lib3mf strict for 3MF,
the Khronos glTF-Validator for glTF), and the verdicts are compared:

* 3MF: every must-fail file lib3mf strict rejects is flagged, and in all
  at least as many must-fail files as lib3mf strict rejects; every
  must-pass file lib3mf strict reads is read, and every example too but
  those requiring an extension the checker does not read (named);
* glTF: of the files the validator calls valid, at most 5 are refused
  (holding no triangles is not a refusal), each with a reason that names
  the feature; every compressed file made by an independent encoder reads;
* every file: no internal error, and checked in under 30 s.
"""

from __future__ import annotations

import conformance as cf
import pytest

MAX_SECONDS = 30.0


@pytest.fixture(scope="module", params=sorted(cf.SUITES))
def rows(request: pytest.FixtureRequest) -> list[cf.Row]:
    files = cf.suite_files(request.param)
    assert files, f"no files for suite {request.param} in {cf.SUITES[request.param][0]}"
    return cf.run_suite(request.param)


def _listing(rows: list[cf.Row]) -> str:
    return "\n".join(f"  {r.name}: {r.reason} (reference: {r.reference} {r.reference_message})" for r in rows)


def test_no_file_of_any_suite_is_an_internal_error_or_slow(rows: list[cf.Row]) -> None:
    bad = [r for r in rows if "internal_error" in r.codes]
    assert not bad, "internal errors:\n" + _listing(bad)
    slow = [r for r in rows if r.elapsed_s > MAX_SECONDS]
    assert not slow, f"over {MAX_SECONDS} s:\n" + _listing(slow)


def test_check_agrees_with_the_reference_reader(rows: list[cf.Row]) -> None:
    suite = rows[0].suite
    if suite == "3mf-mustfail":
        missed = [r for r in rows if r.reference == "rejects" and r.outcome != "agree"]
        assert not missed, "must-fail files lib3mf strict rejects but check passes:\n" + _listing(missed)
        flagged = sum(r.outcome == "agree" for r in rows)
        assert flagged >= sum(r.reference == "rejects" for r in rows)
    elif suite == "3mf-mustpass":
        refused = [r for r in rows if r.reference == "reads" and r.verdict == "unreadable"]
        assert not refused, "must-pass files lib3mf strict reads but check refuses:\n" + _listing(refused)
    elif suite == "3mf-examples":  # valid 3MF; some require extensions the checker does not read (beam lattice)
        refused = [r for r in rows if r.reference == "reads" and r.verdict == "unreadable"]
        vague = [r for r in refused if r.codes != ["unsupported_format"] or "extension" not in r.reason]
        assert not vague, "examples lib3mf strict reads but check refuses, not for an extension:\n" + _listing(vague)
        assert len(refused) <= 3, _listing(refused)
    elif suite == "gltf-validator":
        refused = [r for r in rows if r.expected == "valid" and r.outcome == "disagree"]
        assert len(refused) <= 5, f"{len(refused)} valid glTF files refused:\n" + _listing(refused)
        vague = [r for r in refused if r.codes != ["unsupported_format"]]
        assert not vague, "valid glTF refused for a reason that is not an unsupported feature:\n" + _listing(vague)
    else:  # gltf-compressed: valid by construction, and the validator must agree that they are
        assert all(r.reference == "reads" for r in rows), _listing([r for r in rows if r.reference != "reads"])
        refused = [r for r in rows if r.verdict == "unreadable"]
        assert not refused, "compressed glTF refused:\n" + _listing(refused)
