"""Importing saucerfab chooses how torch's OpenMP workers wait, unless the user did (saucerfab/__init__.py)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

SHOW = "import os, saucerfab; print(os.environ.get('OMP_WAIT_POLICY'), os.environ.get('GOMP_SPINCOUNT'))"


@pytest.mark.parametrize(
    ("given", "seen"),
    [
        ({}, "PASSIVE 20000"),
        ({"GOMP_SPINCOUNT": "7"}, "PASSIVE 7"),  # the user's spin count, waiting passively after it
        ({"OMP_WAIT_POLICY": "ACTIVE"}, "ACTIVE None"),  # the user's policy, and libgomp's spin for it
    ],
)
def test_openmp_wait_settings(given, seen):
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    out = subprocess.run([sys.executable, "-c", SHOW], env={**env, **given}, capture_output=True, text=True,
                         check=True)
    assert out.stdout.split() == seen.split()
