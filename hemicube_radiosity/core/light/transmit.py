"""Surfaces light passes through: alpha cut-outs and transparent shaders, on shadow and sky rays.

Cycles lets a shadow ray through a Transparent BSDF (a Principled BSDF's Alpha below 1 is a mix
with one) without bending it, its throughput times the transparent share, up to
``transparent_max_bounces`` surfaces (8 by default). A leaf modelled as one plane with an image
whose alpha cuts its outline is lit through its holes; a plane of Alpha 0.5 passes half the light.

Each source mesh may carry a :class:`Transmit` (``MeshInput.transmit``): per face a uniform
transmittance (the scalar share passed straight through, 0 opaque, 1 not there) or an image
whose alpha is read where a ray crosses the face, through the face's UVs. :func:`see_through`
gathers them over the meshes of a bake into a :class:`SeeThrough`: the see-through faces as
triangles (fans of each face's corners, with their UVs), which faces of which mesh they are
(a face's back from :mod:`..mesh.backs` with it), and the images.
:class:`SeeThroughScene` casts shadow rays: the opaque patches block as before (their outlines,
:func:`..rays.occluder`), and each see-through triangle a ray crosses multiplies its throughput
by the transmittance at the crossing, up to :data:`LAYERS` of them.

The final gather's rays pass them too (:mod:`..output.through`): a gather ray takes (1 - t) of
a see-through surface it lands on, read at the face's colour (the solve's reflectance over its
mean opacity, ``SeeThrough.opacity``), and goes on with t for what lies behind. So do the
hemi-cube's form factors (:mod:`..form_factors.hemicube`, the default method): a pixel that sees
a see-through patch of mean transmittance t (``SeeThrough.passes``) gives 1 - t of its weight to
it and t to what lies behind, one layer deep, and the solve solves for the light of the patch's
solid part, its reflectance (Cycles' albedo, which carries the alpha,
:mod:`...blender.read.shading`) over 1 - t (:func:`..solve.stage.see_through_system`). The
Embree form-factor methods still see a see-through patch as a surface that hides what is
behind it.
Direct light (lamps, emitting faces, the world) and the world's light through the sky rays pass.
Transmittance is one value for the three bands (a coloured Transparent BSDF passes its mean).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["AlphaImage", "Transmit", "SeeThrough", "SeeThroughScene", "see_through", "visibility", "first_visible", "LAYERS"]

#: at most this many see-through surfaces a shadow ray crosses (Cycles' transparent_max_bounces
#: default); a ray meeting more is blocked, as Cycles' is
LAYERS = 8


@dataclass
class AlphaImage:
    """One image's transmittance, read at UVs: ``pixels`` (H, W) float32, 1 - alpha, row 0 at
    v = 0 (Blender's pixel order); ``closest`` nearest pixel, else bilinear (Cycles' Linear);
    ``repeat`` wraps UVs outside [0, 1] (Cycles' Repeat), else clamps them (Extend)."""

    pixels: np.ndarray
    closest: bool = False
    repeat: bool = True

    def at(self, uv: np.ndarray) -> np.ndarray:
        """(M,) transmittance at UVs (M, 2)."""
        H, W = self.pixels.shape
        x = uv[:, 0] * W - 0.5
        y = uv[:, 1] * H - 0.5
        if self.closest:
            return self._texel(np.floor(x + 0.5), np.floor(y + 0.5))
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        return ((1 - fx) * (1 - fy) * self._texel(x0, y0) + fx * (1 - fy) * self._texel(x0 + 1, y0)
                + (1 - fx) * fy * self._texel(x0, y0 + 1) + fx * fy * self._texel(x0 + 1, y0 + 1))

    def _texel(self, x, y):
        H, W = self.pixels.shape
        x, y = x.astype(np.int64), y.astype(np.int64)
        if self.repeat:
            x, y = x % W, y % H
        else:
            x, y = np.clip(x, 0, W - 1), np.clip(y, 0, H - 1)
        return self.pixels[y, x].astype(np.float64)


@dataclass
class Transmit:
    """What of one mesh light passes through.

    face_transmit: (F,) float in [0, 1], the share passed straight through each face (0 opaque)
                   where it has no image.
    face_image:    (F,) int or None, index into ``images`` of the image whose transmittance is read
                   on each face (-1: none, ``face_transmit`` applies).
    corner_uv:     (L,) x 2 float or None, the UVs those images are read through, at every face
                   corner (``MeshInput.face_indices`` order).
    images:        list of :class:`AlphaImage`.
    """

    face_transmit: np.ndarray
    face_image: np.ndarray | None = None
    corner_uv: np.ndarray | None = None
    images: list = field(default_factory=list)

    def opacity(self, face_offsets, samples: int = 8) -> np.ndarray:
        """(F,) the share of each face light does not pass: 1 - its transmittance, for a face
        with an image the mean over ``samples`` x ``samples`` points of each triangle of its
        fan in UV space, weighted by the triangles' UV areas."""
        out = 1.0 - np.asarray(self.face_transmit, float)
        if self.face_image is None or not np.any(np.asarray(self.face_image) >= 0):
            return out
        off = np.asarray(face_offsets, np.int64)
        faces = np.flatnonzero(np.asarray(self.face_image) >= 0)
        n = off[faces + 1] - off[faces]
        face = np.repeat(faces, n - 2)
        k = np.arange(face.size) - np.repeat(np.cumsum(n - 2) - (n - 2), n - 2)
        uv = np.asarray(self.corner_uv, float)[np.stack([off[face], off[face] + k + 1, off[face] + k + 2], 1)]
        i, j = np.meshgrid(np.arange(samples), np.arange(samples), indexing="ij")
        a, b = (i.ravel() + 1 / 3) / samples, (j.ravel() + 1 / 3) / samples
        a, b = np.where(a + b > 1, 1 - a, a), np.where(a + b > 1, 1 - b, b)      # fold into the triangle
        e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) + 1e-30
        pts = uv[:, None, 0] + a[None, :, None] * e1[:, None] + b[None, :, None] * e2[:, None]
        img = np.asarray(self.face_image, np.int64)[face]
        t = np.empty(pts.shape[:2])
        for m in np.unique(img):
            t[img == m] = self.images[m].at(pts[img == m].reshape(-1, 2)).reshape(-1, pts.shape[1])
        sums = np.bincount(face, weights=area * (1 - t.mean(axis=1)), minlength=len(out))
        out[faces] = sums[faces] / np.bincount(face, weights=area, minlength=len(out))[faces]
        return out

    def faces(self) -> np.ndarray:
        """(F,) bool: the faces any light passes through."""
        out = np.asarray(self.face_transmit, float) > 0
        if self.face_image is not None:
            out |= np.asarray(self.face_image) >= 0
        return out


@dataclass
class SeeThrough:
    """The see-through faces of a bake's meshes.

    tris:      (T, 3, 3) float64 triangles (fans of the faces), world space.
    uv:        (T, 3, 2) float64 their corners' UVs (zeros where no image is read).
    transmit:  (T,) float64 uniform transmittance of each, where ``image`` is -1.
    image:     (T,) int64 index into ``images`` or -1.
    images:    list of :class:`AlphaImage`.
    faces:     per mesh of the bake, (F,) bool, its see-through faces (a back's with its front's).
    opacity:   (T,) float64 the mean opacity of each triangle's face (:meth:`Transmit.opacity`:
               what the solve's reflectance carries), or None (read as 1).
    passes:    per mesh of the bake, (F,) float64, each face's mean transmittance (1 - its mean
               opacity; 0 where opaque; a back's its front's), or None (unknown: read as 0).
    """

    tris: np.ndarray
    uv: np.ndarray
    transmit: np.ndarray
    image: np.ndarray
    images: list
    faces: list
    opacity: np.ndarray | None = None
    passes: list | None = None
    _key: bytes | None = field(default=None, repr=False, compare=False)

    def key(self) -> bytes:
        """Bytes that change when what passes changes (faces, values, images); made once."""
        import hashlib

        if self._key is None:
            h = hashlib.sha256()
            for a in [self.tris, self.uv, self.transmit, self.image, *self.faces] + [i.pixels for i in self.images]:
                a = np.ascontiguousarray(a)
                h.update(str(a.shape).encode() + a.tobytes())
            h.update(repr([(i.closest, i.repeat) for i in self.images]).encode())
            self._key = h.digest()
        return self._key

    def patch_mask(self, patches) -> np.ndarray:
        """(N,) bool: the patches cut from see-through faces."""
        flags = np.concatenate([f for f in self.faces] + [np.zeros(0, bool)])
        base = np.concatenate([[0], np.cumsum([len(f) for f in self.faces])]).astype(np.int64)
        owner = np.asarray(patches.owner, np.int64)
        ok = owner < len(self.faces)
        out = np.zeros(len(owner), bool)
        out[ok] = flags[base[owner[ok]] + np.asarray(patches.source_face, np.int64)[ok]]
        return out

    def patch_transmit(self, patches) -> np.ndarray:
        """(N,) float64: the mean transmittance of each patch's face (0 where opaque)."""
        owner = np.asarray(patches.owner, np.int64)
        out = np.zeros(len(owner))
        if self.passes is None:
            return out
        flat = np.concatenate([np.asarray(p, float) for p in self.passes] + [np.zeros(0)])
        base = np.concatenate([[0], np.cumsum([len(p) for p in self.passes])]).astype(np.int64)
        ok = owner < len(self.passes)
        out[ok] = flat[base[owner[ok]] + np.asarray(patches.source_face, np.int64)[ok]]
        return out

    def at(self, prim, u, v) -> np.ndarray:
        """(M,) transmittance where rays crossed triangles ``prim`` (M,) at barycentrics (u, v)."""
        prim = np.asarray(prim, np.int64)
        out = self.transmit[prim].copy()
        img = self.image[prim]
        for k in np.unique(img[img >= 0]):
            sel = img == k
            t = self.uv[prim[sel]]
            uu, vv = np.asarray(u, float)[sel, None], np.asarray(v, float)[sel, None]
            out[sel] = self.images[k].at((1 - uu - vv) * t[:, 0] + uu * t[:, 1] + vv * t[:, 2])
        return np.clip(out, 0.0, 1.0)


def see_through(meshes) -> SeeThrough | None:
    """The see-through faces of ``meshes`` (``MeshInput``s of one bake, backs included), or None
    when light passes through none of them (the bake then casts its rays as always)."""
    flags = [None] * len(meshes)
    for i, m in enumerate(meshes):
        tr = getattr(m, "transmit", None)
        if tr is not None and m.back_of < 0:
            flags[i] = tr.faces()
    if not any(f is not None and f.any() for f in flags):
        return None
    for i, m in enumerate(meshes):                 # a back is see-through where its front is
        if flags[i] is None:
            front = flags[m.back_of] if m.back_of >= 0 else None
            flags[i] = front[np.asarray(m.back_faces)] if front is not None \
                else np.zeros(len(m.face_offsets) - 1, bool)
    parts, images, passes = [], [], [np.zeros(len(f)) for f in flags]
    for i, m in enumerate(meshes):
        if m.back_of >= 0 or not flags[i].any():
            continue
        opacity = m.transmit.opacity(m.face_offsets)
        passes[i] = np.where(flags[i], 1.0 - opacity, 0.0)
        parts.append(_fans(m, np.flatnonzero(flags[i]), len(images), opacity))
        images += list(m.transmit.images)
    for i, m in enumerate(meshes):
        if m.back_of >= 0:
            passes[i] = passes[m.back_of][np.asarray(m.back_faces, np.int64)]
    cat = [np.concatenate([p[k] for p in parts]) for k in range(5)]
    return SeeThrough(*cat[:4], images=images, faces=flags, opacity=cat[4], passes=passes)


def _fans(mesh, faces, image_base, opacity):
    """(tris (T,3,3), uv (T,3,2), transmit (T,), image (T,), opacity (T,)) of ``faces`` of
    ``mesh``, each a fan from its first corner; ``opacity`` (F,): the faces' mean opacity
    (:meth:`Transmit.opacity`)."""
    tr = mesh.transmit
    off = np.asarray(mesh.face_offsets, np.int64)
    n = off[faces + 1] - off[faces]
    face = np.repeat(faces, n - 2)
    k = np.arange(face.size) - np.repeat(np.cumsum(n - 2) - (n - 2), n - 2)
    corners = np.stack([off[face], off[face] + k + 1, off[face] + k + 2], 1)       # (T, 3) loops
    verts = np.asarray(mesh.verts, float)[np.asarray(mesh.face_indices, np.int64)[corners]]
    uv = np.zeros(corners.shape + (2,)) if tr.corner_uv is None \
        else np.asarray(tr.corner_uv, float)[corners]
    image = np.full(face.size, -1, np.int64) if tr.face_image is None \
        else np.asarray(tr.face_image, np.int64)[face]
    image = np.where(image >= 0, image + image_base, -1)
    return verts, uv, np.asarray(tr.face_transmit, float)[face], image, np.asarray(opacity, float)[face]


class SeeThroughScene:
    """Shadow rays through see-through faces: ``opaque`` (anything with ``occluded``: the
    scene of the patches light does not pass) blocks, each see-through triangle crossed
    multiplies the ray's throughput by its transmittance there (:meth:`transmitted`).
    ``scale``: the scene's size; a ray steps 1e-6 of it past each crossing. Needs embreex."""

    see_through = True

    def __init__(self, opaque, st: SeeThrough, scale: float):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self.opaque, self.st, self.step = opaque, st, 1e-6 * float(scale or 1.0)
        self._scene = rtcore_scene.EmbreeScene()
        self._mesh = TriangleMesh(self._scene, np.ascontiguousarray(st.tris, dtype=np.float32))
        # built (committed) here, before threads or forked workers share it
        self._scene.run(np.zeros((1, 3), np.float32), np.array([[0.0, 0.0, 1.0]], np.float32), output=1)

    def transmitted(self, origins, directions, tfar=None) -> np.ndarray:
        """(M,) float64 in [0, 1]: the share of light passing along ``origin + t * direction``,
        0 < t < ``tfar`` (None: no end): 0 where an opaque surface lies on it, else the product
        of the transmittances of the see-through surfaces it crosses (0 past :data:`LAYERS`)."""
        o = np.array(origins, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        tf = np.full(len(o), np.inf) if tfar is None else np.array(tfar, dtype=np.float64).reshape(-1)
        out = (~np.asarray(self.opaque.occluded(origins, directions, tfar), bool)).astype(np.float64)
        live = np.flatnonzero(out > 0)
        step = self.step / np.maximum(np.linalg.norm(d, axis=1), 1e-300)    # in t units
        for _ in range(LAYERS + 1):
            if not live.size:
                break
            far = np.where(np.isfinite(tf[live]), tf[live], 3.0e38).astype(np.float32)
            res = self._scene.run(np.ascontiguousarray(o[live], np.float32),
                                  np.ascontiguousarray(d[live], np.float32), output=1, dists=far)
            prim = np.asarray(res["primID"], np.int64)
            hit = prim >= 0
            live = live[hit]
            if not live.size:
                break
            t = np.asarray(res["tfar"], np.float64)[hit]
            out[live] *= self.st.at(prim[hit], res["u"][hit], res["v"][hit])
            adv = t + step[live]
            o[live] += adv[:, None] * d[live]
            tf[live] -= adv
            live = live[(out[live] > 0) & (tf[live] > 0)]
        else:
            out[live] = 0.0                  # more see-through surfaces than a ray crosses
        return out

    def occluded(self, origins, directions, tfar=None) -> np.ndarray:
        """(M,) bool: no light passes (:meth:`transmitted` is 0)."""
        return self.transmitted(origins, directions, tfar) <= 0.0


def visibility(scene, origins, directions, tfar=None) -> np.ndarray:
    """(M,) the share of light passing each ray: float from a :class:`SeeThroughScene`, else
    bool ``~occluded`` (so scenes without see-through faces give what they always gave)."""
    if getattr(scene, "see_through", False):
        return scene.transmitted(origins, directions, tfar)
    return ~np.asarray(scene.occluded(origins, directions, tfar), bool)


def first_visible(occ, org, d, tf, r, head, N, k):
    """(M,) :func:`visibility` of M rays (``org``, ``d``, ``tf`` or None) of points ``r``
    (M,) in [0, N): the ``head`` (M,) bool rays first; a point with all ``k`` of them that all
    pass (or none does) takes 1 (or 0) for its other rays, the others cast theirs."""
    vis = np.empty(len(r))
    h, rest = np.flatnonzero(head), np.flatnonzero(~head)
    vis[h] = visibility(occ, org[h], d[h], None if tf is None else tf[h])
    count = np.bincount(r[h], minlength=N)
    lit = np.bincount(r[h], weights=vis[h], minlength=N)
    known = ((count == k) & ((lit == 0) | (lit == k)))[r[rest]]
    vis[rest[known]] = (lit[r[rest[known]]] > 0).astype(np.float64)
    cast = rest[~known]
    vis[cast] = visibility(occ, org[cast], d[cast], None if tf is None else tf[cast])
    return vis
