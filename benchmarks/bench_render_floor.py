"""The least time the soft rasterizer's iteration could take on this machine (issue 18).

``bench_render.py`` times one optimizer iteration (both views, 512 x 512, an
L2 loss, gradients to heights and colours). This script splits that
iteration, in one process and on the same arguments, into:

* **kernels**: the forward and backward tile kernels
  (``soft_kernels.forward`` / ``backward``), replayed on the arguments one
  real iteration handed them (both views);
* **pair arithmetic**: the same kernels with the packing of pairs into lane
  groups and the forward's write-back of state taken out, so what is left is
  each pair's arithmetic plus the tiles' set-up and output. The lane loops
  are branch-free (selects and masks, flush-to-zero on), so their cost does
  not depend on the values they read;
* **tile base**: the kernels with every (face, tile) entry skipped: the
  tiles' set-up and output alone;
* **torch work**: the iteration with the rasterizer replaced by an autograd
  op that returns a stored image and alpha and zero gradients: the bench's
  loss, autograd, concatenations and colour gathers, which any rasterizer
  leaves in the iteration;
* **other passes** = iteration - kernels - torch work: projection, face
  set-up, binning, the backward's per-pixel state, face gradients, scatter.

``floor = pair arithmetic + torch work``: an iteration that spent nothing on
packing, write-back, binning, face set-up, backward state, face gradients or
projection; the last column also leaves out the tile base (the tiles' set-up
and output, which any tiled kernel pays in some form). If the floor is above a target, no reorganisation of this
formulation's work reaches the target on this machine; only less arithmetic
per pair, fewer pairs, or other hardware would.

The two variants are built from ``saucerfab/render/soft_kernels.py``'s source
by inserting skips at named places; if the kernels change so that a place is
gone, the script stops and says which. Usage::

    .venv/bin/python benchmarks/bench_render_floor.py [--repeat 15] [--sigmas 1e-5 1e-7]
"""

from __future__ import annotations

import saucerfab  # noqa: F401 - first, as in the CLI: its OpenMP wait settings must precede torch

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import os  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402
from types import ModuleType  # noqa: E402
from typing import Any, Callable  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_render  # noqa: E402
from saucerfab.render import soft_kernels  # noqa: E402
from saucerfab.render.soft_tiles import one_tile_chunks  # noqa: E402

#: the issue's targets, ms per iteration on this machine
TARGETS_MS = {1e-5: 35.0, 1e-7: 25.0}

#: (what the edit does, the exact source text, its replacement); ``{skip_pack}`` and
#: ``{skip_entries}`` become the variant's compile-time constants (numba folds a
#: module global into the compiled code)
_EDITS = [
    ("the variant compiles afresh (no cache beside a temporary file)",
     "from saucerfab.render.soft_tiles import JIT_OPTS,",
     "from saucerfab.render.soft_tiles import JIT_OPTS as _JIT_OPTS,"),
    ("the variant's constants",
     "#: inlined into the caller",
     "JIT_OPTS = {{**_JIT_OPTS, 'cache': False}}\nSKIP_PACK = {skip_pack}\nSKIP_ENTRIES = {skip_entries}\n\n"
     "#: inlined into the caller"),
    ("forward: skip an entry",
     "        if rb < ra or cbx < ca:\n            continue\n",
     "        if rb < ra or cbx < ca or SKIP_ENTRIES:\n            continue\n"),
    ("forward: pack no pairs",
     "            _pack_row(scr, total, px_tab, ca, py, st, q0, NLOC, w)\n",
     "            if not SKIP_PACK:\n                _pack_row(scr, total, px_tab, ca, py, st, q0, NLOC, w)\n"),
    ("forward: no write-back of the state",
     "        # write the state back",
     "        if SKIP_PACK:\n            continue\n        # write the state back"),
    ("backward: skip an entry",
     "        if rb >= ra and cbx >= ca:\n",
     "        if rb >= ra and cbx >= ca and not SKIP_ENTRIES:\n"),
    ("backward: pack no pairs",
     "                _pack_row(scr, total, px_tab, ca + lo, py, bst,",
     "                if not SKIP_PACK:\n                    _pack_row(scr, total, px_tab, ca + lo, py, bst,"),
]


def variant_source(source: str, skip_pack: bool, skip_entries: bool) -> str:
    """``soft_kernels``' source with the skips of one variant inserted.

    Raises:
        SystemExit: a place to edit is not (or not exactly once) in the source.
    """
    for what, old, new in _EDITS:
        n = source.count(old)
        if n != 1:
            raise SystemExit(
                f"bench_render_floor: cannot build the variant ({what}): {old!r} occurs {n} times in "
                "saucerfab/render/soft_kernels.py; update _EDITS to the kernels' new text"
            )
        source = source.replace(old, new.format(skip_pack=skip_pack, skip_entries=skip_entries))
    return source


def load_variant(name: str, source: str, folder: Path) -> ModuleType:
    """Import ``source`` as module ``name`` from a file in ``folder``."""
    path = folder / f"{name}.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise SystemExit(f"bench_render_floor: cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def capture(work: tuple) -> dict[str, list[list[Any]]]:
    """The arguments of every forward and backward kernel call of one iteration, copied
    right after each call (the backward's per-pixel state lives in a buffer the next
    call reuses)."""
    calls: dict[str, list[list[Any]]] = {"forward": [], "backward": []}
    saved = {name: getattr(soft_kernels, name) for name in calls}

    def wrap(name: str) -> Callable[..., Any]:
        def call(*args: Any) -> Any:
            out = saved[name](*args)
            calls[name].append([a.copy() if isinstance(a, np.ndarray) else a for a in args])
            return out
        return call

    try:
        for name in calls:
            setattr(soft_kernels, name, wrap(name))
        bench_render.iteration(*work, backend="numba")
    finally:
        for name, fn in saved.items():
            setattr(soft_kernels, name, fn)
    return calls


def replay(module: ModuleType, calls: dict[str, list[list[Any]]], name: str) -> None:
    """One iteration's calls of kernel ``name`` (both views), as the backend runs them."""
    fn = getattr(module, name)
    with one_tile_chunks():
        for args in calls[name]:
            fn(*args)


def median_ms(fn: Callable[[], Any], repeat: int) -> tuple[float, float]:
    """(median, min) milliseconds of ``fn`` over ``repeat`` calls, after one untimed call."""
    fn()
    ts = bench_render.timed(fn, repeat)
    return 1e3 * statistics.median(ts), 1e3 * min(ts)


def torch_work_iteration(work: tuple) -> Callable[[], Any]:
    """The bench's iteration with the rasterizer replaced by stored outputs and zero gradients."""
    heights, views, colors, targets, sigma = work
    stored = []
    with torch.no_grad():
        for verts, faces, ids, cam in views(heights):
            cf = colors if ids is None else torch.index_select(colors, 0, ids)
            stored.append(bench_render.soft_rasterize(verts, faces, cf, cam, sigma=sigma, backend="numba"))

    class Stored(torch.autograd.Function):
        @staticmethod
        def forward(ctx, verts, cf, k):  # type: ignore[no-untyped-def]
            ctx.shapes = verts.shape, cf.shape
            image, alpha = stored[k]
            return image.clone(), alpha.clone()

        @staticmethod
        def backward(ctx, g_image, g_alpha):  # type: ignore[no-untyped-def]
            return torch.zeros(ctx.shapes[0]), torch.zeros(ctx.shapes[1]), None

    calls = [0]  # the views come in the same order every iteration

    def fake(verts, faces, cf, cam, sigma, backend):  # type: ignore[no-untyped-def]
        k = calls[0] % len(stored)
        calls[0] += 1
        return Stored.apply(verts, cf, k)

    def run() -> None:
        real = bench_render.soft_rasterize
        bench_render.soft_rasterize = fake
        try:
            bench_render.iteration(*work, backend="numba")
        finally:
            bench_render.soft_rasterize = real

    return run


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15, help="timed calls of each part")
    ap.add_argument("--sigmas", type=float, nargs="+", default=[1e-5, 1e-7])
    args = ap.parse_args(argv)
    if args.repeat < 1:
        ap.error(f"--repeat must be at least 1 (got {args.repeat}): each part's median needs a timed call")
    if any(not s > 0 for s in args.sigmas):
        ap.error(f"--sigmas must be positive (got {args.sigmas}): sigma is the coverage sigmoid's width")

    heights, views, colors, _ = bench_render.build_problem()
    rng = np.random.default_rng(0)
    targets = [
        (torch.as_tensor(rng.random((cam.image_size, cam.image_size, 3)), dtype=torch.float32),
         torch.ones(cam.image_size, cam.image_size))
        for _, _, _, cam in views(heights)
    ]
    source = Path(soft_kernels.__file__).read_text()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        variants = {
            "kernels": soft_kernels,
            "pair arithmetic": load_variant("_floor_arith", variant_source(source, True, False), Path(tmp)),
            "tile base": load_variant("_floor_base", variant_source(source, True, True), Path(tmp)),
        }
        for sigma in args.sigmas:
            work = (heights, views, colors, targets, sigma)
            bench_render.iteration(*work, backend="numba")  # compile or load the cache
            bench_render._numba_ran = True
            calls = capture(work)
            row: dict[str, Any] = {"sigma": sigma}
            row["iteration"] = median_ms(lambda: bench_render.iteration(*work, backend="numba"), args.repeat)
            for label, module in variants.items():
                for name in ("forward", "backward"):
                    row[label, name] = median_ms(lambda: replay(module, calls, name), args.repeat)
            row["torch work"] = median_ms(torch_work_iteration(work), args.repeat)
            rows.append(row)
            print(f"sigma {sigma:g}: " + ", ".join(
                f"{k if isinstance(k, str) else ' '.join(k)} {v[0]:.1f}" for k, v in row.items() if k != "sigma"
            ) + " ms (medians)", flush=True)
    print(report(rows, args))
    return 0


def report(rows: list[dict[str, Any]], args: argparse.Namespace) -> str:
    load = os.getloadavg()
    lines = [
        "# The rasterizer's floor on this machine (benchmarks/bench_render_floor.py)",
        "",
        f"Machine: {bench_render.machine()}. Load average at the end: {load[0]:.2f} / {load[1]:.2f} / "
        f"{load[2]:.2f}. Command: `.venv/bin/python benchmarks/bench_render_floor.py --repeat {args.repeat}`. "
        f"Medians of {args.repeat} calls, ms per iteration (both views); kernels = forward + backward.",
        "",
        "| sigma | iteration | kernels (fwd + bwd) | pair arithmetic | tile base | packing + write-back "
        "| other passes | torch work | floor = arithmetic + torch | the same without the tile base | target |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        def both(label: str) -> float:
            return float(r[label, "forward"][0] + r[label, "backward"][0])

        it, kern, arith, base, torch_ms = (
            r["iteration"][0], both("kernels"), both("pair arithmetic"), both("tile base"), r["torch work"][0]
        )
        target = TARGETS_MS.get(r["sigma"])
        lines.append(
            f"| {r['sigma']:g} | {it:.1f} | {kern:.1f} ({r['kernels', 'forward'][0]:.1f} + "
            f"{r['kernels', 'backward'][0]:.1f}) | {arith:.1f} ({r['pair arithmetic', 'forward'][0]:.1f} + "
            f"{r['pair arithmetic', 'backward'][0]:.1f}) | {base:.1f} | {kern - arith:.1f} "
            f"| {it - kern - torch_ms:.1f} | {torch_ms:.1f} | **{arith + torch_ms:.1f}** "
            f"| {arith - base + torch_ms:.1f} "
            f"| {'-' if target is None else f'{target:g}'} |"
        )
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
