"""The sparse spike stage alone, under the choices it depends on (issue 4).

Runs the enhanced Laplacian stages of the full method once on the bundled
samples (as ``bench_design.py``; cached with ``--cache``), then the sparse
stage from that h^e for every combination of sigma, lambda factor (times the
paper's 6e-5 rho), prox step alpha and fraction-to-boundary rule given, and
prints per run: iterations, why it stopped, the vertices that moved more than
1e-4, E_sparse, E_deform and the final E_visual (hard textured renders against
the inputs, as in the ablation; lower is better). The first line is h^e
itself, i.e. setting (c) of Figure 11.

    .venv/bin/python benchmarks/bench_sparse_stage.py --sigmas 1e-7,1e-5 --lam 1,0.3 --alpha 0.2,1
    .venv/bin/python benchmarks/bench_sparse_stage.py --rules global,coordinate --cache /tmp/he.npz

This is what decided the stage's sigma (1e-5) and its per-coordinate
boundary rule; ``benchmarks/results/HISTORY.md``, "Design (issue 4)", has the figures.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import saucerfab  # noqa: E402, F401 - before torch: its OpenMP wait settings (saucerfab/__init__.py)

import numpy as np  # noqa: E402
import torch  # noqa: E402

from saucerfab.model.design import Design  # noqa: E402
from saucerfab.model.heightfield import laplacian  # noqa: E402
from saucerfab.optimize.energies import DeformEnergy, barrier_floor, e_barrier, e_visual  # noqa: E402
from saucerfab.optimize.prepare import prepare  # noqa: E402
from saucerfab.optimize.previews import final_visual_error  # noqa: E402
from saucerfab.optimize.request import DesignRequest  # noqa: E402
from saucerfab.optimize.solver import ProxSettings, SolverSettings, solve  # noqa: E402
from saucerfab.optimize.stages import ABLATION_STAGES, SIGMA_LARGE, WEIGHT_FACTORS  # noqa: E402
from saucerfab.optimize.targets import blur_matched_targets, compatibility  # noqa: E402
from saucerfab.optimize.texturing import texture_saucer  # noqa: E402
from saucerfab.optimize.views import Rig  # noqa: E402


def floats(text: str) -> list[float]:
    return [float(x) for x in text.split(",")]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--barrier-weight", type=float, default=0.01)
    p.add_argument("--sigmas", type=floats, default=[1e-7, 1e-5])
    p.add_argument("--lam", type=floats, default=[1.0], help="factors on lambda = 6e-5 rho")
    p.add_argument("--alpha", type=floats, default=[0.2], help="prox steps (paper: 0.2)")
    p.add_argument("--rules", default="coordinate", help="fraction-to-boundary rules: global,coordinate")
    p.add_argument("--cache", type=Path, help="npz for h^e and the colours (reused when it exists)")
    args = p.parse_args()

    samples = ROOT / "samples"
    mu = args.barrier_weight
    req = DesignRequest(samples / "direct_heart.png", samples / "reflected_star.png", shape="waves",
                        frames="contain", barrier_weight=mu, ablation="laplacian_bw")
    prep = prepare(req)
    scene, n = prep.scene, prep.scene.saucer.resolution
    delta, dtype = scene.saucer.delta, torch.float32
    rig = Rig(scene, prep.base, reflected_groups=prep.reflected_groups)
    z = torch.as_tensor(prep.base.reshape(-1), dtype=dtype)
    deform = DeformEnergy(laplacian(n), z)
    cache: dict[float, list] = {}

    def targets(sigma: float) -> list:
        if sigma not in cache:
            t = blur_matched_targets(rig, prep.base, prep.enhanced, sigma, dtype=dtype)
            cache[sigma] = [t[v.name] for v in rig.views]
        return cache[sigma]

    rho = compatibility(rig, prep.base, prep.enhanced, {v.name: t for v, t in zip(rig.views, targets(SIGMA_LARGE))},
                        SIGMA_LARGE, dtype=dtype)
    weights = {k: f * rho for k, f in WEIGHT_FACTORS.items()}
    floor = mu * barrier_floor(rig.num_vertices, rig.num_faces, delta)

    def stage(h, c, sigma, w, rule="global", prox=None):  # type: ignore[no-untyped-def]
        tl = targets(sigma)

        def objective(hh: torch.Tensor, cc: torch.Tensor):  # type: ignore[no-untyped-def]
            ev = e_visual(rig.render(hh, cc, sigma), tl)
            return ev + w * deform(hh) + mu * e_barrier(hh, z, cc, delta), {}

        settings = SolverSettings(lr_h=delta / 20, energy_floor=floor, boundary_rule=rule)
        return solve(objective, h, c, z, delta, settings, prox=prox)

    def final(h: torch.Tensor) -> float:
        heights = h.numpy().astype(np.float64).reshape(n, n)
        tex = texture_saucer(rig, heights, prep.texture)
        d = Design(scene=scene, heights=heights, base_heights=prep.base, texture=tex.texture,
                   face_uvs=tex.face_uvs, face_view=tex.face_view)
        return final_visual_error(d, rig, prep)["E_visual_final"]

    if args.cache and args.cache.exists():
        data = np.load(args.cache)
        h, c = torch.as_tensor(data["h"]), torch.as_tensor(data["c"])
    else:
        h, c = z + 0.0, torch.full((rig.num_faces, 3), 0.5, dtype=dtype)
        for spec in ABLATION_STAGES["laplacian_bw"]:
            res = stage(h, c, spec.sigma, weights[spec.weight])
            h, c = res.h, res.c
            print(f"{spec.name}: {res.iterations} iterations ({res.stop_reason}), {res.seconds:.1f} s", flush=True)
        if args.cache:
            np.savez(args.cache, h=h.numpy(), c=c.numpy())
    margin = delta - (h - z).abs()
    print(f"rho {rho:.4g}, lambda {weights['lam']:.4g}; h^e: smallest distance to a bound {float(margin.min()):.2g}")
    print(f"(c) h^e itself: final E_visual {final(h):.1f}, E_deform {float(deform(h)):.4f}")
    print(f"{'sigma':>7s} {'lam x':>6s} {'alpha':>6s} {'rule':>10s} {'iters':>5s} {'stop':>12s} "
          f"{'moved':>6s} {'E_sparse':>8s} {'E_deform':>8s} {'E_visual':>9s} {'s':>5s}")
    for sigma, lf, alpha, rule in itertools.product(args.sigmas, args.lam, args.alpha, args.rules.split(",")):
        t0 = time.perf_counter()
        prox = ProxSettings(center=h.clone(), lam=weights["lam"] * lf, alpha=alpha)
        res = stage(h, c, sigma, 0.0, rule, prox)
        dh = (res.h - h).abs()
        print(f"{sigma:7.0e} {lf:6.2g} {alpha:6.2g} {rule:>10s} {res.iterations:5d} {res.stop_reason:>12s} "
              f"{int((dh > 1e-4).sum()):6d} {float(dh.sum()):8.3f} {float(deform(res.h)):8.4f} "
              f"{final(res.h):9.1f} {time.perf_counter() - t0:5.1f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
