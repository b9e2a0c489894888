"""Compile saucerfab's numba kernels once: ``python -m saucerfab.warmup``.

numba compiles a kernel on its first call and caches the machine code beside
the sources (``cache=True``). Running this after installing means the first
design or export does not pay several seconds of compile time; ``make
install`` runs it. Kernels that cannot be compiled here are reported, not fatal.
"""

from __future__ import annotations

import sys
import time


def warm_up_check() -> list[str]:
    """Compile the checker's numba kernels (large meshes, meshopt, the OBJ and 3MF bulk parsers); return their names."""
    from saucerfab.check.kernels_warmup import warm_up as kernels_warm_up
    from saucerfab.check.readers.meshopt import warm_up as meshopt_warm_up
    from saucerfab.check.readers.obj_fast import warm_up as obj_warm_up
    from saucerfab.check.readers.threemf_fast import warm_up as threemf_warm_up

    return [f"check.{k}" for k in (*kernels_warm_up(), *meshopt_warm_up(), *obj_warm_up(), *threemf_warm_up())]


def warm_up(*, check: bool = True) -> list[str]:
    """Compile every numba kernel on tiny inputs (the checker's unless ``check`` is False); return what was warmed."""
    import numpy as np

    done: list[str] = []
    from saucerfab.fabricate.kernels import warm_up as fab_warm_up

    done += [f"fabricate.{k}" for k in fab_warm_up()]
    from saucerfab.model.relief import blunt_thin_crests

    spike = np.zeros((5, 5))
    spike[2, 2] = 3.0
    blunt_thin_crests(spike, 0.5, 0.5, 0.3, min_wall=1.0)  # both wall kernels (relief_kernels.py)
    done.append("relief.wall_kernels")
    if check:
        done += warm_up_check()

    import torch

    from saucerfab.render import Camera, rasterize_hard, soft_rasterize

    cam = Camera((0.0, -5.0, 5.0), (0.0, 0.0, 0.0), 10.0, 16)
    v = torch.tensor([[-0.3, -0.3, 0.0], [0.3, -0.3, 0.0], [0.0, 0.3, 0.0]], dtype=torch.float32, requires_grad=True)
    f = torch.tensor([[0, 1, 2]])
    c = torch.full((1, 3), 0.5, requires_grad=True)
    for dtype in (torch.float32, torch.float64):
        img, _ = soft_rasterize(v.to(dtype), f, c.to(dtype), cam)
        img.sum().backward()
    done.append("render.soft_rasterize")
    rasterize_hard(np.asarray(v.detach()), np.asarray(f), cam)
    done.append("render.rasterize_hard")
    return done


def main() -> int:
    import subprocess

    t0 = time.perf_counter()
    # numba compiles on one core: the checker's kernels compile in a second process meanwhile (each kernel
    # has its own cache file, so the two never write the same one)
    code = "from saucerfab.warmup import warm_up_check; print(len(warm_up_check()))"
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        names = warm_up(check=False)
    except Exception as exc:
        print(f"saucerfab warm-up skipped: {exc}", file=sys.stderr)
        names = []
    out, err = child.communicate()
    if child.returncode == 0:
        names += ["check"] * int(out.strip() or 0)
    else:
        print(f"saucerfab warm-up of the checker's kernels skipped: {err.strip().splitlines()[-1:]}", file=sys.stderr)
    print(f"saucerfab: compiled {len(names)} kernels in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
