"""The design folder's safety and its checkpoint: refuse an ``--out`` that holds a user's data, resume.

:func:`check_output_folder` refuses, before any work, an output path whose
replacement would lose data; :class:`Checkpoint` keeps the optimised state
after each stage (and on Ctrl-C) beside the folder, keyed by
:func:`request_hash`, so the same request run again resumes instead of
optimising again (:func:`saucerfab.optimize.pipeline.optimize_design`).
"""

from __future__ import annotations

import hashlib
import json
import shutil
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab import __version__
from saucerfab.errors import ConfigError
from saucerfab.files.fileio import write_bytes_atomic
from saucerfab.optimize.prepare import Prepared
from saucerfab.optimize.request import DesignRequest


def check_output_folder(out: Path, force: bool = True) -> None:
    """Refuse, before any work, an output path whose replacement would lose a user's data.

    The design folder is written atomically and replaces ``out`` when done;
    that is only safe when ``out`` does not exist, is an empty folder, or is
    an earlier design folder (it holds ``design.json``). With ``force``
    False an earlier design folder is refused too (the CLI without
    ``--force``); the library's default replaces it, as batch reruns need.
    """
    if not out.exists():
        return
    if not out.is_dir():
        raise ConfigError(f"--out {str(out)!r} is an existing file; give a new or empty folder for the design")
    if any(out.iterdir()) and not (out / "design.json").is_file():
        raise ConfigError(
            f"--out {str(out)!r} is a non-empty folder that is not a design folder; saucerfab would "
            "replace it. Give a new or empty folder, or remove it first"
        )
    if not force and (out / "design.json").is_file():
        raise ConfigError(
            f"--out {str(out)!r} already holds a design; writing this one would replace it. "
            "Give a new folder, or add --force to replace it"
        )


def request_hash(request: DesignRequest, prepared: Prepared) -> str:
    """Hash of everything that determines the result (for resume and batch)."""
    d = asdict(request)
    for k, v in list(d.items()):
        if isinstance(v, Path):
            d[k] = str(v)
    payload = json.dumps({"req": d, "inputs": prepared.inputs, "v": __version__}, sort_keys=True, default=str)
    return hashlib.sha256(payload.encode()).hexdigest()


class Checkpoint:
    """The optimised state after each finished stage, beside the design folder ``out`` (``.<name>.checkpoint``).

    A run of the same request (the same :func:`request_hash`) resumes from it; a finished run clears it.
    """

    def __init__(self, out: Path, key: str) -> None:
        self.dir = out.parent / f".{out.name}.checkpoint"
        self.key = key

    def load(self) -> dict[str, Any] | None:
        f = self.dir / "state.npz"
        if not f.is_file():
            return None
        try:
            with np.load(f, allow_pickle=False) as z:
                if str(z["key"]) != self.key:
                    return None
                return {
                    "stage": int(z["stage"]),
                    "h": z["h"],
                    "c": z["c"],
                    "log": json.loads(str(z["log"])),
                    "metrics": json.loads(str(z["metrics"])),
                    "weights": json.loads(str(z["weights"])),
                    # wall time of earlier runs up to the saved state (0 in older checkpoints)
                    "elapsed_s": float(z["elapsed_s"]) if "elapsed_s" in z.files else 0.0,
                }
        except (OSError, ValueError, KeyError):
            return None  # a damaged checkpoint is ignored; the run starts afresh

    def save(
        self, stage: int, h: np.ndarray, c: np.ndarray, log: list, metrics: dict, weights: dict, elapsed_s: float = 0.0
    ) -> None:
        import io

        buf = io.BytesIO()
        np.savez(
            buf,
            key=np.array(self.key),
            stage=np.array(stage),
            h=h,
            c=c,
            log=np.array(json.dumps(log)),
            metrics=np.array(json.dumps(metrics)),
            weights=np.array(json.dumps(weights)),
            elapsed_s=np.array(float(elapsed_s)),
        )
        write_bytes_atomic(self.dir / "state.npz", buf.getvalue())

    def clear(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)
