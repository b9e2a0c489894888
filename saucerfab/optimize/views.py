"""The view rig: the saucer seen directly and in the mirror, as meshes to rasterize.

Since vertices move only in z and the cup is a vertical cylinder, the
reflected xy of every saucer vertex is computed once (:mod:`saucerfab.model.mirror`);
a reflected vertex is ``(r_x, r_y, h)`` with the saucer vertex's height. Each
view is therefore a fixed xy array, a gather index into ``h``, a face list and
a gather index into the per-face colours ``c``, so rendering a view is one
concatenation and one call of the soft rasterizer, differentiable in ``h`` and ``c``.

Which reflected vertices are valid (T on the visible part of the cup, between
its bottom and rim) is decided from the heights the rig is built with; the
optimizer moves heights by less than delta, which moves T by less than delta
in height, so the face sets stay fixed during a stage.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from saucerfab.model.camera import Camera
from saucerfab.model.footprint import design_vertices, direct_vertices
from saucerfab.model.heightfield import make_grid, triangulate
from saucerfab.model.scene import Scene

if TYPE_CHECKING:
    import torch

#: the rendered images' background (where no face covers a pixel)
BACKGROUND = (1.0, 1.0, 1.0)


@dataclass
class ViewMesh:
    """One view's mesh, as numpy arrays (:class:`View`: the same as torch tensors).

    Attributes:
        name: "direct", "reflected" or "reflected2".
        camera: the view's camera.
        xy: (V', 2) fixed xy of the view's vertices, model units.
        vert_src: (V',) int64, saucer vertex each view vertex takes its height from.
        faces: (F', 3) int64 into the view's vertices.
        face_src: (F',) int64, saucer face each view face takes its colour from.
    """

    name: str
    camera: Camera
    xy: np.ndarray | torch.Tensor
    vert_src: np.ndarray | torch.Tensor
    faces: np.ndarray | torch.Tensor
    face_src: np.ndarray | torch.Tensor
    #: the direct view takes every vertex and face in order: no gather needed
    identity: bool = False
    #: a reflected view's (V', 5) float64 mirror at each vertex: T's xy, the cup's outward
    #: normal there, the prism facet (-1: smooth cup); None for the direct view
    mirror: np.ndarray | None = None

    def vertices_np(self, h: np.ndarray) -> np.ndarray:
        """(V', 3) float64 vertices for saucer heights ``h`` ((N, N) or (V,), model units)."""
        z = np.asarray(h, np.float64).reshape(-1)[np.asarray(self.vert_src), None]
        return np.concatenate([np.asarray(self.xy).astype(np.float64), z], axis=1)


@dataclass
class View(ViewMesh):
    """One rendered view: a :class:`ViewMesh` whose arrays are torch tensors (on the CPU)."""

    def vertices(self, h: torch.Tensor) -> torch.Tensor:
        """(V', 3) vertices for saucer heights ``h`` (V,)."""
        import torch

        hv = h if self.identity else h.index_select(0, self.vert_src)
        return torch.cat([self.xy.to(h.dtype), hv.unsqueeze(1)], dim=1)

    def colors(self, c: torch.Tensor) -> torch.Tensor:
        """(F', 3) colours of the view's faces from the saucer's (F, 3).

        index_select, not ``c[face_src]``: its backward (index_add) is much
        faster on the CPU than advanced indexing's (index_put, accumulate).
        """
        return c if self.identity else c.index_select(0, self.face_src)


class ViewMeshes:
    """The saucer's views for one scene and resolution as numpy meshes (the torch-free part of :class:`Rig`).

    What the first look renders before torch is imported; :class:`Rig` is
    built from one and has the same attributes, its views as torch tensors.

    Args:
        scene: the scene (its saucer resolution sets N).
        heights: (N, N) heights used to decide the reflected faces' validity.
        image_size: rendered image size S (default: the scene's).
        reflected_groups: for prism cups in two-reflection mode, the facet
            indices of each reflected image, e.g. ``[[0, 1], [4, 5]]``;
            None renders every visible facet into one reflected view.
    """

    def __init__(
        self,
        scene: Scene,
        heights: np.ndarray,
        image_size: int | None = None,
        reflected_groups: list[list[int]] | None = None,
    ) -> None:
        from saucerfab.model.mirror import reflect

        self.scene = scene
        n = scene.saucer.resolution
        self.n = n
        self.grid = make_grid(scene.saucer)
        self.faces_np = triangulate(n)
        xy = self.grid.xy()
        self.xy = xy
        nv, nf = n * n, self.faces_np.shape[0]
        self.num_vertices, self.num_faces = nv, nf
        size_d = image_size or scene.direct.image_size
        size_r = image_size or scene.reflected.image_size
        cam_d = Camera.from_scene(scene, "direct").with_size(size_d)
        h_flat = np.asarray(heights, np.float64).reshape(-1)
        #: (V,) bool: vertices that carry the design (a rectangle: all; a disc: on it, clear of the cup)
        self.design_vertices = design_vertices(scene, xy)
        if scene.saucer.is_disc:  # the disc's faces the eye sees as design, the cup hiding those behind it
            seen = direct_vertices(scene, self.grid.vertices(h_flat))
            self.views: list[Any] = [self._gather("direct", cam_d, seen)]
        else:
            self.views = [ViewMesh("direct", cam_d, xy, np.arange(nv), self.faces_np, np.arange(nf), identity=True)]
        pieces = reflect(scene, xy)
        self.pieces = pieces
        groups: list[tuple[str, list]] = []
        if reflected_groups is None:
            groups.append(("reflected", pieces))
        else:
            names = ["reflected", "reflected2"]
            if len(reflected_groups) > len(names):
                raise ValueError("at most two reflected images are supported")
            for name, facets in zip(names, reflected_groups):
                groups.append((name, [p for p in pieces if p.facet in set(facets)]))
        for name, group in groups:
            xs, srcs, faces, fsrc, mirror = [], [], [], [], []
            offset = 0
            for piece in group:
                ok = piece.valid(h_flat, scene.cup.height) & self.design_vertices
                face_ok = ok[self.faces_np].all(axis=1)
                if not face_ok.any():
                    continue
                keep = np.flatnonzero(ok)
                remap = np.full(nv, -1, np.int64)
                remap[keep] = np.arange(keep.size) + offset
                xs.append(piece.r_xy[keep])
                srcs.append(keep)
                faces.append(remap[self.faces_np[face_ok]])
                fsrc.append(np.flatnonzero(face_ok))
                mirror.append(np.concatenate([piece.t_xy[keep], piece.normal_xy[keep],
                                              np.full((keep.size, 1), float(piece.facet))], axis=1))
                offset += keep.size
            if not faces:
                xs, srcs, faces, fsrc = [np.zeros((0, 2))], [np.zeros(0, np.int64)], [np.zeros((0, 3), np.int64)], [np.zeros(0, np.int64)]
                mirror = [np.zeros((0, 5))]
            self.views.append(
                ViewMesh(
                    name,
                    Camera.from_scene(scene, name).with_size(size_r),
                    np.concatenate(xs),
                    np.concatenate(srcs),
                    np.concatenate(faces),
                    np.concatenate(fsrc),
                    mirror=np.concatenate(mirror),
                )
            )
        self.views = [self.as_view(v) for v in self.views]
        #: supersample -> (heights (V,), samples per face) of the last :meth:`face_samples` call
        self._visible_memo: dict[int, tuple[np.ndarray, dict[str, np.ndarray]]] = {}

    def _gather(self, name: str, camera: Camera, keep_vertices: np.ndarray) -> ViewMesh:
        """The view of the faces whose three vertices are kept, seen in place (no mirror)."""
        face_ok = keep_vertices[self.faces_np].all(axis=1)
        keep = np.flatnonzero(keep_vertices)
        remap = np.full(self.num_vertices, -1, np.int64)
        remap[keep] = np.arange(keep.size)
        return ViewMesh(name, camera, self.xy[keep], keep, remap[self.faces_np[face_ok]], np.flatnonzero(face_ok))

    def design_faces(self) -> np.ndarray:
        """(F,) bool: the grid's faces that carry the design (a rectangle: all; a disc: on it, clear of the cup)."""
        return self.design_vertices[self.faces_np].all(axis=1)

    def visible_faces(self, heights: np.ndarray, supersample: int = 2) -> dict[str, np.ndarray]:
        """Per view, (F,) bool: saucer faces that cover a (super)sample of its picture (the rectangle of the
        frame's ``extent``) in that view, at ``heights`` (N, N) or (V,) (:meth:`face_samples` > 0)."""
        return {name: n > 0 for name, n in self.face_samples(heights, supersample).items()}

    def face_samples(self, heights: np.ndarray, supersample: int = 2) -> dict[str, np.ndarray]:
        """Per view, (F,) int64: how many of the view's (super)samples inside its picture each saucer face covers.

        A face's share of a view's picture, in samples of ``supersample`` x its render size per side:
        what the texturing weighs a face seen in two views by. The last result per ``supersample`` is
        kept (fresh copies are returned): a design's last stage classifies its final heights and the
        texturing right after asks for the same, with single-sampled looks in between.
        """
        from saucerfab.render import rasterize_hard

        h = np.asarray(heights, np.float64).reshape(-1)
        kept = self._visible_memo.get(supersample)
        if kept is not None and np.array_equal(kept[0], h):
            return {name: n.copy() for name, n in kept[1].items()}
        out = {}
        for view in self.views:
            count = np.zeros(self.num_faces, np.int64)
            if view.faces.shape[0]:
                cam = view.camera.with_size(view.camera.image_size * supersample)
                fid, _, _ = rasterize_hard(view.vertices_np(h), view.faces, cam)
                extent = frame_extent(self.scene, view.name)
                if extent != (1.0, 1.0):  # seen in the picture's rectangle: the square's padding is surround
                    fid = np.where(inside_extent(cam, extent), fid, -1)
                hits = np.bincount(fid[fid >= 0], minlength=view.faces.shape[0])
                np.add.at(count, np.asarray(view.face_src), hits)  # a face mirrored twice (a prism) adds up
            out[view.name] = count
        self._visible_memo[supersample] = (h.copy(), {name: n.copy() for name, n in out.items()})
        return out

    def as_view(self, mesh: ViewMesh) -> Any:
        """A view as this class keeps it (numpy here; :class:`Rig`: torch tensors)."""
        return mesh

    def view(self, name: str) -> Any:
        """The view called ``name`` (a :class:`ViewMesh`; a :class:`View` in a :class:`Rig`)."""
        for v in self.views:
            if v.name == name:
                return v
        raise KeyError(name)


class Rig(ViewMeshes):
    """The saucer's views for one scene and resolution, as torch tensors to render.

    Args: as :class:`ViewMeshes`.
    """

    views: list[View]

    def as_view(self, mesh: ViewMesh) -> View:
        import torch

        return View(mesh.name, mesh.camera, torch.as_tensor(mesh.xy), torch.as_tensor(mesh.vert_src),
                    torch.as_tensor(mesh.faces), torch.as_tensor(mesh.face_src), identity=mesh.identity,
                    mirror=mesh.mirror)

    def render(
        self,
        h: torch.Tensor,
        c: torch.Tensor,
        sigma: float,
        *,
        views: list[str] | None = None,
        backend: str = "auto",
    ) -> list[torch.Tensor]:
        """Soft-rasterize each view: a list of (S, S, 3) images, differentiable in h and c.

        Args:
            h: (V,) heights. c: (F, 3) per-face colours.
            sigma: SoftRas sigma.
        """
        from saucerfab.render import soft_rasterize

        out = []
        for v in self.views:
            if views is not None and v.name not in views:
                continue
            img, _ = soft_rasterize(
                v.vertices(h),
                v.faces,
                v.colors(c),
                v.camera,
                sigma=sigma,
                background=BACKGROUND,
                backend=backend,
            )
            out.append(img)
        return out

    def picture_masks(self) -> list[torch.Tensor | None]:
        """Per view, None when its picture fills its square, else an (S, S, 1) 0/1 tensor of the pixels
        whose centres lie in the picture's rectangle (the frame's ``extent``): E_visual scores those
        only, the square's rest is the surround (:mod:`saucerfab.optimize.surround`)."""
        import torch

        out: list[torch.Tensor | None] = []
        for v in self.views:
            extent = frame_extent(self.scene, v.name)
            out.append(None if extent == (1.0, 1.0) else
                       torch.as_tensor(inside_extent(v.camera, extent), dtype=torch.float32).unsqueeze(-1))
        return out

    def reflected_face_mask(self) -> np.ndarray:
        """(F,) bool: saucer faces that take part in any reflected view."""
        m = np.zeros(self.num_faces, bool)
        for v in self.views[1:]:
            m[v.face_src.numpy()] = True
        return m


def frame_extent(scene: Scene, view: str) -> tuple[float, float]:
    """The extent of ``view``'s picture in its square frame (a missing reflected2 frame: reflected's)."""
    frame = getattr(scene, view, None) or scene.reflected
    return (float(frame.extent[0]), float(frame.extent[1]))


def inside_extent(camera: Camera, extent: tuple[float, float]) -> np.ndarray:
    """(S, S) bool: the pixels of ``camera`` whose centres lie in the rectangle ``|x| <= ex, |y| <= ey`` (NDC)."""
    xs, ys = camera.pixel_ndc()
    return (np.abs(ys)[:, None] <= extent[1]) & (np.abs(xs)[None, :] <= extent[0])


def visible_faces(rig: ViewMeshes, heights: np.ndarray, supersample: int = 2) -> dict[str, np.ndarray]:
    """Per view, (F,) bool: saucer faces that cover a (super)sample in that view (:meth:`ViewMeshes.visible_faces`)."""
    return rig.visible_faces(heights, supersample)
