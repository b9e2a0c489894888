"""Benchmark: export a 150 x 150 design with a 4096 x 4096 atlas (target: <= 15 s).

    .venv/bin/python benchmarks/bench_export.py [--runs 2] [--px 4096] [--n 150]

The design is synthetic but shaped like a real one: the paper's 150 x 150
grid on the corrugated ("waves") saucer, a 1024 px image-like texture
(smooth colour fields with sharp edges), and the back slopes of the ridges
marked as seen by no viewer (about a third of the faces), so the harmonic
fill of unseen areas runs at full size. All six formats are written (3MF,
OBJ, GLB, PLY, VRML, STL) plus scene.json and export.json.

Reference, in the same run: the plain path without colour - manifold3d's
solid, then trimesh's own export of that untextured solid (OBJ, GLB, PLY,
STL; trimesh's 3MF writer needs lxml, which saucerfab does not depend on).

The first run in a process includes loading numba and its cached kernels
(and compiling them the first time on a machine); later runs are warm.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np


def bench_design(n: int):  # -> Design
    from saucerfab.model.design import FaceView
    from saucerfab.model.design_folder import synthetic_design

    d = synthetic_design(resolution=n, shape="waves", texture_size=64, seed=0)
    rng = np.random.default_rng(0)
    size = 1024
    y, x = np.mgrid[0:size, 0:size] / size
    img = np.zeros((size, size, 3))
    for c in range(3):
        for _ in range(6):
            fx, fy, ph = rng.uniform(1, 8), rng.uniform(1, 8), rng.uniform(0, 2 * np.pi)
            img[..., c] += np.sin(2 * np.pi * (fx * x + fy * y) + ph)
    img = (img - img.min()) / (img.max() - img.min()) * 200 + 20
    img[(np.floor(x * 16) + np.floor(y * 16)) % 2 == 0] *= 0.6  # sharp edges, like a black-white design
    img += rng.normal(0, 4, img.shape)  # texel-scale grain
    texture = np.clip(img, 0, 255).astype(np.uint8)
    # faces on the ridges' back slopes (normals facing +y, away from the viewer) are unseen
    v = d.vertices()
    f = d.faces()
    nrm = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    view = np.where(nrm[:, 1] > 0.05 * np.linalg.norm(nrm, axis=1), FaceView.NEITHER, FaceView.DIRECT)
    return replace(d, texture=texture, face_view=view.astype(np.uint8))


def machine() -> str:
    model = platform.processor() or "?"
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=False).stdout
        for line in out.splitlines():
            if line.startswith("Model name:"):
                model = line.split(":", 1)[1].strip()
    except OSError:
        pass
    return f"{model}, nproc {os.cpu_count()}, Python {platform.python_version()}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=150, help="grid vertices per side")
    ap.add_argument("--px", type=int, default=4096, help="atlas edge, pixels")
    ap.add_argument("--runs", type=int, default=2, help="export runs (the first is cold)")
    args = ap.parse_args()

    from saucerfab.fabricate.options import FabOptions
    from saucerfab.fabricate.pipeline import export_design
    from saucerfab.files.formats import FORMATS
    from saucerfab.model.profiles import load_profile
    from saucerfab.fabricate.solid import build_solid

    design = bench_design(args.n)
    unseen = float((design.face_view == 0).mean())
    # the J55's limits, accepting every format so all writers run
    profile = replace(load_profile("j55"), accepted_formats=FORMATS)
    options = FabOptions(texture_px=args.px)
    tmp = Path(tempfile.mkdtemp(prefix="bench_export_"))
    print(f"machine: {machine()}")
    print(f"design: {args.n} x {args.n} grid, {design.faces().shape[0]} faces, {unseen:.0%} unseen; atlas {args.px} px")
    try:
        runs = []
        for k in range(args.runs):
            t0 = time.perf_counter()
            res = export_design(design, tmp / f"out{k}", printer=profile, formats=list(FORMATS), options=options)
            runs.append((time.perf_counter() - t0, res))
        # reference: the same solid without colour, exported by trimesh
        import trimesh

        t0 = time.perf_counter()
        solid = build_solid(design, design.scene.mm_per_unit, options, profile)
        t_solid = time.perf_counter() - t0
        mesh = trimesh.Trimesh(solid.vertices, solid.faces, process=False)
        ref = {}
        for ft in ("obj", "glb", "ply", "stl"):
            t0 = time.perf_counter()
            data = mesh.export(file_type=ft)
            ref[ft] = (time.perf_counter() - t0, len(data))
        same = all((tmp / "out0" / p.name).read_bytes() == p.read_bytes() for p in (tmp / f"out{len(runs) - 1}").iterdir())
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    steps = list(runs[0][1].timings)
    print()
    print(f"{'step':16s}" + "".join(f"{'run ' + str(i + 1) + (' (cold)' if i == 0 else ''):>16s}" for i in range(len(runs))))
    for s in steps:
        print(f"{s:16s}" + "".join(f"{r.timings.get(s, 0.0):16.3f}" for _, r in runs))
    print(f"{'total (wall)':16s}" + "".join(f"{t:16.3f}" for t, _ in runs))
    res = runs[-1][1]
    print()
    print(f"triangles {res.triangles}, volume {res.volume_mm3 / 1000:.1f} cm3, bbox {' x '.join(f'{b:.1f}' for b in res.bbox_mm)} mm")
    print("files: " + ", ".join(f"{k} {v / 1e6:.1f} MB" for k, v in sorted(res.file_bytes.items())))
    print(f"identical bytes across runs: {same}")
    print()
    print("reference (no colour): manifold3d solid + trimesh export")
    print(f"{'solid':16s}{t_solid:16.3f}")
    for ft, (t, size) in ref.items():
        print(f"{'trimesh ' + ft:16s}{t:16.3f}   {size / 1e6:.1f} MB")
    print(f"{'total':16s}{t_solid + sum(t for t, _ in ref.values()):16.3f}")
    best = min(t for t, _ in runs)
    print()
    print(f"target <= 15 s: {'met' if max(t for t, _ in runs) <= 15 else 'NOT met'} (best {best:.2f} s, cold {runs[0][0]:.2f} s)")


if __name__ == "__main__":
    main()
