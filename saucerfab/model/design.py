"""A design: the saucer's heights and texture, the scene, and what it was made for.

:class:`Design` is what the optimizer makes (:func:`saucerfab.workflow.run_design`
returns it) and what export, verify and the pages read; :class:`Intent` is
the designer's intent it carries (the printer, the cup's size, the eyes, the
frames), so every later stage defaults from the design rather than from its
own default. The design *folder* on disk (``design.json``, the arrays, the
pictures) is :mod:`saucerfab.model.design_folder`.

Grid and face order follow :mod:`saucerfab.model.heightfield` (``triangulate(N)``).
Texture coordinates follow the OBJ/glTF-independent convention used in all
of saucerfab: ``u`` from left (0) to right (1) of the texture image, ``v``
from bottom (0) to top (1), i.e. pixel row ``(1 - v) * H``. UVs are per face
corner because a vertex shared by a face textured from the direct image and
one textured from the reflected image has two texture coordinates.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import IntEnum
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.errors import DesignError
from saucerfab.model.eyes import DEFAULT_IPD_MM, EyeSpec, parse_eyes
from saucerfab.model.heightfield import make_grid, triangulate
from saucerfab.model.scene import VIEW_NAMES, Scene, ViewFrame

#: a printer key a design.json records: a design folder may come from anyone, so what it
#: records is only ever looked up among the installation's profiles, not read from a file
PROFILE_KEY_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")


@dataclass(frozen=True)
class Intent:
    """What a design was made for: the defaults of every stage after the design (issue 41).

    Read from design.json's ``parameters`` and scene by :meth:`of`, the one
    reader of them; a value a design does not record (a synthetic design,
    one older than the field, a damaged file) is None, and each stage then
    keeps its own default.

    Attributes:
        printer: the key of the printer profile it was made for (``saucerfab
            design --printer``, or the key ``parameters.print_target`` records
            when the profile was a .toml file). Only keys, never paths: a
            design folder may come from anyone, and its printer is looked up
            among this installation's profiles.
        printer_name: the profile's display name as recorded, or None.
        cup_diameter_mm: the real cup's width across its footprint, mm (the scene's; None
            when read without a scene).
        eyes: the eyes it was made for (``--eyes both|box:...``), None for the
            design eye alone: verify renders from these by default.
        frames: view name -> the frame it was designed with (the scene's),
            the picture's rectangle in it (``extent``); empty when read without a scene.
    """

    printer: str | None
    printer_name: str | None
    cup_diameter_mm: float | None
    eyes: EyeSpec | None
    frames: Mapping[str, ViewFrame]

    @classmethod
    def of(cls, parameters: Any, scene: Scene | None = None) -> Intent:
        """The intent that ``parameters`` (design.json's, any JSON value) and ``scene`` record.

        Without ``scene`` (a print folder's export.json, a batch job reading design.json
        alone) the cup's size and the frames are left out.
        """
        params = parameters if isinstance(parameters, dict) else {}
        target = params.get("print_target")
        target = target if isinstance(target, dict) else {}
        printer = None
        for made in (params.get("printer"), target.get("printer")):
            if isinstance(made, str) and PROFILE_KEY_RE.fullmatch(made):
                printer = made
                break
        name = target.get("printer_name")
        return cls(
            printer=printer,
            printer_name=name if isinstance(name, str) else None,
            cup_diameter_mm=None if scene is None else float(scene.cup_diameter_mm),
            eyes=_eyes(params),
            frames={} if scene is None else {v: getattr(scene, v) for v in VIEW_NAMES if getattr(scene, v) is not None},
        )


def _eyes(params: Mapping[str, Any]) -> EyeSpec | None:
    """The eyes ``--eyes`` recorded (with ``ipd_mm`` for ``both``), None for the design eye or a value not read."""
    from saucerfab.errors import ConfigError

    eyes, ipd = params.get("eyes"), params.get("ipd_mm")
    if not isinstance(eyes, str):
        return None
    if isinstance(ipd, bool) or not isinstance(ipd, (int, float)):
        ipd = DEFAULT_IPD_MM
    try:
        spec = parse_eyes(eyes, float(ipd))
    except ConfigError:
        return None
    return None if spec.mode == "design" else spec


@dataclass(frozen=True)
class StageRecord:
    """One optimisation stage as design.json's ``metrics.stages`` records it.

    Attributes:
        name: the stage's name (:mod:`saucerfab.optimize.stages`).
        iterations: accepted iterations.
        E_visual: the stage's final visual energy, against its (blur-matched) targets.
        E_deform: its final deformation energy.
        conflict_fraction: the share of framed faces both views see, 0..1.
        stop_reason: why it ended (``saucerfab.optimize.solver``'s words), or None.
        seconds: its wall time, None when the design was made with ``--no-times``.
    """

    name: str
    iterations: int
    E_visual: float
    E_deform: float
    conflict_fraction: float
    stop_reason: str | None
    seconds: float | None

    @classmethod
    def of(cls, entry: Mapping[str, Any]) -> StageRecord:
        """The record of one ``metrics.stages`` entry (missing numbers are NaN, a missing name empty)."""
        def num(key: str) -> float:
            v = entry.get(key)
            return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else float("nan")

        seconds = entry.get("seconds")
        return cls(
            name=str(entry.get("name", "")),
            iterations=int(entry.get("iterations", 0) or 0),
            E_visual=num("E_visual"),
            E_deform=num("E_deform"),
            conflict_fraction=num("conflict_fraction"),
            stop_reason=entry.get("stop_reason") if isinstance(entry.get("stop_reason"), str) else None,
            seconds=float(seconds) if isinstance(seconds, (int, float)) and not isinstance(seconds, bool) else None,
        )


class FaceView(IntEnum):
    """Texturing case of a face (paper, section 3.4.2; SURROUND beyond it)."""

    NEITHER = 0
    DIRECT = 1
    REFLECTED = 2
    BOTH = 3
    #: seen by the design eye outside every frame (directly or in the cup): textured with
    #: that view's background (:mod:`saucerfab.optimize.surround`)
    SURROUND = 4


#: the cases of faces some frame sees (the paper's three): what a conflict share counts
FRAMED_VIEWS = (FaceView.DIRECT, FaceView.REFLECTED, FaceView.BOTH)


@dataclass
class Design:
    """A finished (or synthetic) design.

    Attributes:
        scene: the scene it was designed for.
        heights: (N, N) float64 final heights, model units.
        base_heights: (N, N) float64 base shape, model units.
        texture: (H, W, 3) uint8 sRGB texture image.
        face_uvs: (F, 3, 2) float32 per-corner texture coordinates in [0, 1].
        face_view: (F,) uint8 texturing case per face (:class:`FaceView`).
        parameters: the parameters it was made with (free-form, JSON-able).
        metrics: per-stage metrics (free-form, JSON-able).
        inputs: input names and sha256 hashes.
        references: view name -> (T, T, 3) uint8, the input picture as meant
            (fitted and flattened); empty for a synthetic design.
        folder: the design folder it was read from or written to, None for
            one only in memory.
    """

    scene: Scene
    heights: np.ndarray
    base_heights: np.ndarray
    texture: np.ndarray
    face_uvs: np.ndarray
    face_view: np.ndarray
    parameters: dict[str, Any] = field(default_factory=dict)
    metrics: dict[str, Any] = field(default_factory=dict)
    inputs: dict[str, Any] = field(default_factory=dict)
    references: dict[str, np.ndarray] = field(default_factory=dict)
    folder: Path | None = None

    @property
    def intent(self) -> Intent:
        """What it was made for (:class:`Intent`): the later stages' defaults."""
        return Intent.of(self.parameters, self.scene)

    @property
    def stage_records(self) -> tuple[StageRecord, ...]:
        """The optimisation's stages as ``metrics.stages`` records them, in order (empty for a synthetic design)."""
        entries = self.metrics.get("stages", [])
        return tuple(StageRecord.of(e) for e in entries if isinstance(e, Mapping)) if isinstance(entries, list) else ()

    @property
    def n(self) -> int:
        return int(self.heights.shape[0])

    def faces(self) -> np.ndarray:
        return triangulate(self.n)

    def vertices(self) -> np.ndarray:
        return make_grid(self.scene.saucer).vertices(self.heights)

    def validate(self) -> None:
        """Raise :class:`DesignError` if arrays disagree with each other or the scene."""
        n = self.scene.saucer.resolution
        f = 2 * (n - 1) ** 2
        checks = [
            (self.heights.shape == (n, n), f"heights {self.heights.shape} != ({n}, {n})"),
            (self.base_heights.shape == (n, n), f"base_heights {self.base_heights.shape} != ({n}, {n})"),
            (self.face_uvs.shape == (f, 3, 2), f"face_uvs {self.face_uvs.shape} != ({f}, 3, 2)"),
            (self.face_view.shape == (f,), f"face_view {self.face_view.shape} != ({f},)"),
            (
                self.texture.ndim == 3 and self.texture.shape[2] == 3 and self.texture.dtype == np.uint8,
                f"texture must be (H, W, 3) uint8, got {self.texture.shape} {self.texture.dtype}",
            ),
            (bool(np.isfinite(self.heights).all()), "heights hold NaN or infinite values"),
            (bool(np.isfinite(self.face_uvs).all()), "face_uvs hold NaN or infinite values"),
        ]
        for ok, msg in checks:
            if not ok:
                raise DesignError(f"inconsistent design: {msg}")


