# SPDX-License-Identifier: GPL-3.0-or-later
"""The direct light at a lightmap's texels, exact only where the light needs it.

A texel's direct light is exact (:meth:`..light.direct.DirectLight.split_at`, each source apart)
at the corners of a coarse grid of texels (every :data:`STRIDES`-th row and column), laid on
each face from its first row and column of texels, its last cells cut (narrower) at its last
row and column: a small island (Lightmap Pack gives every face one; half the living room's
1,961 are 42 texels or fewer) is covered by cells to its border, and a strip one texel wide by
cells along it (with the image's fixed grid, whose cells crossed the islands' borders, every
island's last row and column and the 2-texel grid's anchors were lit exactly: 151,389 of the
living room's 507,328 texels in the world's light, 62,697 so). A texel between four such
anchors takes their bilinear interpolation, source by source, where:

* the four anchors and the texel lie on one face of the mesh, and the texel's world point is
  the bilinear interpolation of theirs (within :data:`FLAT` of a texel: the UV map is affine
  there, not folded across an edge, not clamped onto an island's border);
* every source's light is smooth there: within :data:`AGREE` of the largest value, or
  :data:`AGREE_FLOOR` of the source's 99th percentile over the anchors (faint light), as
  below;
* the probe agrees: every emitter and lamp lit with one shadow ray at the texel itself gives
  what the interpolation gives (a shadow thinner than the grid, falling between the anchors,
  is found there), and no texel within :data:`MARGIN` texels disagrees (a penumbra's edge
  beside a shadow whose centre ray the texel sees).

The grids run from coarse to fine (8 texels, 4, then 2); on the 8- and 4-texel grids a cell's
middle (rounded down) is lit exactly too and must read what the corners' interpolation makes of it; a 2-texel cell's
corners must agree, or the light must run straight across it (its second differences through
the anchors beyond it, over 8, within the same bound: a linear ramp of the sky toward a window
is interpolated exactly). A texel no grid settles is lit exactly. Each source is settled
apart: a texel lit exactly in a lamp's light at its shadow's edge takes the world's
interpolation where the world's own light is smooth (its hundreds of rays a point are cast at
its anchors and where it bends: a tenth of a lit floor's texels, not a third).
Both tests compare each source with itself, relative to its own scale: a relight of new
strengths or colours picks the same texels (and finds their rays cached). Smooth light (the
sky on a wall, a lamp's falloff, the sun on a lit floor) costs the anchors, on a small face too;
shadow edges and contacts cost what they did.
"""
from __future__ import annotations

import numpy as np

from ..util.colour import LUMA

__all__ = ["by_source", "as_cycles", "from_inside", "STRIDES", "AGREE", "AGREE_FLOOR", "FLAT", "MARGIN"]

STRIDES = (8, 4, 2)   # texels between the anchors of the grids tried, coarse to fine
AGREE = 0.02          # a source's light at the four anchors within this share of the largest ...
AGREE_FLOOR = 0.002   # ... or of this share of its 99th percentile over the anchors
FLAT = 1.0           # texels: the texel's point off the anchors' bilinear interpolation at most
MARGIN = 2            # texels around a texel whose probe disagrees that are lit exactly too


def _span(x, lo, hi, s):
    """(a, b) (m,) the cell of stride ``s`` along one axis around texel coordinates ``x`` (m,)
    on a face spanning ``lo``..``hi`` (m,): from ``lo`` in steps of ``s``, the last step cut at
    ``hi`` (a + s beyond it: a narrower cell ending on the face's last texel); a == b where
    the face is one texel across (a cell along the other axis only)."""
    k = np.minimum((x - lo) // s, np.maximum(hi - lo - 1, 0) // s)
    a = lo + k * s
    return a, np.minimum(a + s, hi)


def _corners(index, rows, cols, s, box):
    """(m, 4) texel ids (-1 off the image, not covered, or the texel outside its face's
    ``box``) of the anchors around texels at ``rows``, ``cols`` on the grid of stride ``s``
    laid from each face's first row and column (``box`` (rmin, rmax, cmin, cmax) (m,) each:
    the face's texels span those), its last cells cut at the face's last row and column;
    (m, 4) their bilinear weights; (r0, r1, c0, c1) (m,) each the cell's rows and columns."""
    H, W = index.shape
    rmin, rmax, cmin, cmax = box
    (r0, r1), (c0, c1) = _span(rows, rmin, rmax, s), _span(cols, cmin, cmax, s)
    fr = (rows - r0) / np.maximum(r1 - r0, 1)
    fc = (cols - c0) / np.maximum(c1 - c0, 1)
    out = np.full((len(rows), 4), -1, np.int64)
    inbox = (rows >= rmin) & (rows <= rmax) & (cols >= cmin) & (cols <= cmax)
    for k, (r, c) in enumerate(((r0, c0), (r0, c1), (r1, c0), (r1, c1))):
        ok = inbox & (r >= 0) & (r < H) & (c >= 0) & (c < W)
        out[ok, k] = index[r[ok], c[ok]]
    w = np.stack([(1 - fr) * (1 - fc), (1 - fr) * fc, fr * (1 - fc), fr * fc], 1)
    return out, w, (r0, r1, c0, c1)


def _middle(index, span):
    """(m,) the texel id (-1: none) in the middle of each cell ``span`` (r0, r1, c0, c1) (m,)
    (rounded down), and (m, 4) its bilinear weights in the cell."""
    r0, r1, c0, c1 = span
    r, c = (r0 + r1) // 2, (c0 + c1) // 2
    fr = (r - r0) / np.maximum(r1 - r0, 1)
    fc = (c - c0) / np.maximum(c1 - c0, 1)
    w = np.stack([(1 - fr) * (1 - fc), (1 - fr) * fc, fr * (1 - fc), fr * fc], 1)
    H, W = index.shape
    out = np.full(len(r), -1, np.int64)
    ok = (r >= 0) & (r < H) & (c >= 0) & (c < W)
    out[ok] = index[r[ok], c[ok]]
    return out, w


def _boxes(faces, rows, cols, inside=None):
    """(rmin, rmax, cmin, cmax) (n,) each: the rows and columns each texel's face spans (over
    its ``inside`` texels where it has any: an island's rim, clamped onto it, takes its
    neighbours' light, :func:`_rim`)."""
    use = np.ones(len(faces), bool) if inside is None else inside
    out = []
    for x in (rows, cols):
        lo = np.full(int(faces.max()) + 1 if len(faces) else 0, np.iinfo(np.int64).max)
        hi = np.full(lo.shape, -1)
        np.minimum.at(lo, faces[use], x[use])
        np.maximum.at(hi, faces[use], x[use])
        none = hi[faces] < 0                               # a face of rim texels only
        np.minimum.at(lo, faces[none], x[none])
        np.maximum.at(hi, faces[none], x[none])
        out += [lo[faces], hi[faces]]
    return tuple(out)


def _affine(points, corners, w, ids, pitch):
    """(m,) bool: the texels ``ids``' points lie where the bilinear weights ``w`` (m, 4) of their
    ``corners`` (m, 4) put them, within :data:`FLAT` of a texel (``pitch`` (n,) world units)."""
    w = np.broadcast_to(w, corners.shape)
    off = np.einsum("mk,mkj->mj", w, points[corners]) - points[ids]
    return np.linalg.norm(off, axis=1) <= FLAT * pitch[ids]


def _bend(value, done, faces, index, span, face):
    """(m, S) the interpolation's error the light's bend suggests across each texel's cell
    ``span`` (r0, r1, c0, c1) (m,): the largest second difference of each source's luminance
    along the cell's two rows and two columns, through the texels a cell's width beyond it on
    either side (on ``face`` and ``done`` (n, S) in that source; one side where the other has
    none), over 8 (a quadratic's error at a cell's middle); inf where neither side has one."""
    H, W = index.shape
    r0, r1, c0, c1 = span
    hr, hc = r1 - r0, c1 - c0
    out = np.zeros((len(r0), value.shape[1]))

    def at(r, c):
        ok = (r >= 0) & (r < H) & (c >= 0) & (c < W)
        i = np.full(len(r), -1, np.int64)
        i[ok] = index[r[ok], c[ok]]
        ok = i >= 0
        ok[ok] = faces[i[ok]] == face[ok]
        ok = ok[:, None] & done[np.maximum(i, 0)]
        return np.where(ok, value[np.maximum(i, 0)] @ LUMA, np.nan)
    zero = np.zeros_like(hr)
    for r, c, dr, dc in ((r0, c0, zero, hc), (r1, c0, zero, hc), (r0, c0, hr, zero), (r0, c1, hr, zero)):
        a, b, c1_, d = (at(r + k * dr, c + k * dc) for k in (-1, 0, 1, 2))
        both = np.fmax(np.abs(a - 2 * b + c1_), np.abs(b - 2 * c1_ + d))       # either side where one lacks
        flat = ((dr == 0) & (dc == 0))[:, None]                               # no extent: no error
        out = np.maximum(out, np.where(flat, 0.0, np.where(np.isnan(both), np.inf, both)))
    return out / 8


def _near(mask_ids, rows, cols, shape, margin):
    """(H, W) bool: texels within ``margin`` (Chebyshev) of the texels ``mask_ids`` at ``rows``,
    ``cols``."""
    img = np.zeros(shape, bool)
    img[rows[mask_ids], cols[mask_ids]] = True
    out = img.copy()
    H, W = shape
    for dr in range(-margin, margin + 1):
        for dc in range(-margin, margin + 1):
            src = img[max(0, -dr):H - max(0, dr), max(0, -dc):W - max(0, dc)]
            out[max(0, dr):H - max(0, -dr), max(0, dc):W - max(0, -dc)] |= src
    return out


def _agree(a, b, floor):
    """(m, S) bool: luminances ``a`` and ``b`` (m, S) agree (:data:`AGREE`, ``floor`` (S,))."""
    return np.abs(a - b) <= AGREE * np.maximum(a, b) + floor


def _cells(index, faces, rows, cols, ids, s, box):
    """(ok (m,) bool, corners (m, 4), weights (m, 4), middle (m,), its weights (m, 4), span)
    the grid cell of stride ``s`` around each texel ``ids`` (m,), laid on its face's ``box``
    (:func:`_corners`): its anchors and bilinear weights and the texel in its middle (its first
    corner on a 2-texel grid); ``ok`` where all of them are texels of the texel's own face."""
    corners, w, span = _corners(index, rows[ids], cols[ids], s, tuple(b[ids] for b in box))
    if s > 2:
        mid, wm = _middle(index, span)
    else:
        mid, wm = corners[:, 0], np.tile([1.0, 0.0, 0.0, 0.0], (len(ids), 1))
    ok = np.all(corners >= 0, axis=1) & (mid >= 0)
    ok[ok] = np.all(faces[np.column_stack([corners[ok], mid[ok]])] == faces[ids[ok], None], axis=1)
    return ok, corners, w, mid, wm, span


def _floor(value, exact):
    """(S,) :data:`AGREE_FLOOR` of each source's 99th percentile over the texels lit exactly in it."""
    return AGREE_FLOOR * np.array([np.percentile(value[exact[:, k], k] @ LUMA, 99) if exact[:, k].any()
                                   else 0.0 for k in range(value.shape[1])])


def _smooth(value, done, points, pitch, faces, index, ids, corners, w, mid, wm, span, s, floor):
    """(m, S) bool: the texels ``ids`` (m,) whose cell of stride ``s`` (``corners``, weights
    ``w``, middle ``mid`` with weights ``wm``, ``span``) interpolates each source (module
    docstring): the texel not yet done in it, its anchors done, the cell affine; on the 8- and
    4-texel grids the middle agreeing with the corners' interpolation, on the 2-texel grid the
    corners agreeing or the light running straight across (:func:`_bend`)."""
    keep = _affine(points, corners, w, ids, pitch)[:, None] & ~done[ids]            # (m, S)
    keep &= done[corners].all(axis=1) & done[mid]
    Y = value[corners] @ LUMA                                         # (m, 4, S)
    if s > 2:      # the cell's middle, lit exactly, is what the corners' interpolation makes of it
        keep &= _affine(points, corners, wm, mid, pitch)[:, None]
        keep &= _agree(np.einsum("mk,mks->ms", wm, Y), value[mid] @ LUMA, floor)
    else:          # a cell two texels wide: its corners agree, or the light is straight across it
        bend = _bend(value, done, faces, index, span, faces[ids])
        keep &= _agree(Y.max(axis=1), Y.min(axis=1), floor) | (bend <= AGREE * Y.max(axis=1) + floor)
    return keep


def by_source(split, covered, points, normals, faces, pitch, probed=None, inside=None, strides=STRIDES):
    """(n, S, 3) the direct light of each source at the n covered texels (``covered`` (H, W),
    row-major order): exact at the anchors and where that source's light needs it, bilinear
    between anchors elsewhere (module docstring), each source apart: the world is not cast at a
    lamp's shadow edge where its own light is smooth. Also (n, S) bool: the texels lit exactly
    in each source.

    ``split(ids, samples, which=None) -> (m, S, 3)`` the exact light at texels ``ids`` (with
    ``samples`` shadow rays per emitter and lamp: None the bake's, 1 the probe; ``which`` (S,)
    bool or None: only those sources, the others 0); ``points``, ``normals`` (n, 3),
    ``faces`` (n,) each texel's mesh face, ``pitch`` (n,) its side in world units; ``probed``
    (S,) bool: the sources a one-ray probe stands for (emitters and lamps; not the world), None
    for none; ``inside`` (n,) bool or None: texels whose centre lies inside their triangle (the
    others, on an island's rim, take their inside neighbours' light where they have any:
    :func:`_rim`)."""
    H, W = covered.shape
    n = int(covered.sum())
    index = np.full((H, W), -1, np.int64)
    index[covered] = np.arange(n)
    rows, cols = np.nonzero(covered)
    box = _boxes(np.asarray(faces, dtype=np.int64), rows, cols, inside)
    lit = _Lit(split, n)
    floor = probe = None
    for s in strides:
        ids = np.flatnonzero(~lit.done.all(axis=1))
        if ids.size == 0:
            break
        ok, corners, w, mid, wm, span = _cells(index, faces, rows, cols, ids, s, box)
        # each anchor in the sources its cells' texels still want
        anchors = np.column_stack([corners[ok], mid[ok]])
        at, left = anchors.ravel(), np.repeat(~lit.done[ids[ok]], anchors.shape[1], axis=0)
        want = np.stack([np.bincount(at, weights=left[:, k], minlength=n) > 0 for k in range(lit.done.shape[1])], 1)
        a = np.unique(anchors)
        lit.light(a, want[a])
        if floor is None and lit.exact.any():
            floor = _floor(lit.value, lit.exact)
        ids, corners, w, mid, wm = ids[ok], corners[ok], w[ok], mid[ok], wm[ok]
        span = tuple(x[ok] for x in span)
        if ids.size == 0:
            continue
        keep = _smooth(lit.value, lit.done, points, pitch, faces, index, ids, corners, w, mid, wm, span, s, floor)
        interp = np.einsum("mk,mksc->msc", w, lit.value[corners])
        if probed is not None and np.any(probed):
            if probe is None:           # the probed sources only: the world's rays are the costliest
                probe = split(np.arange(n), 1, np.asarray(probed, bool)) @ LUMA        # (n, S)
            for k in np.flatnonzero(probed):
                off = ~_agree(probe[ids, k], interp[:, k] @ LUMA, floor[k])
                keep[:, k] &= ~_near(ids[off], rows, cols, (H, W), MARGIN)[rows[ids], cols[ids]]
        m, k = np.nonzero(keep)
        lit.value[ids[m], k] = interp[m, k]
        lit.done[ids[m], k] = True
    if not lit.exact.any():                         # no cell anywhere: every texel exact
        lit.light(np.arange(n))
    if inside is not None:
        left = np.flatnonzero(~lit.done.all(axis=1) & inside)
        lit.light(left, ~lit.done[left])
        _rim(lit.value, lit.done, inside, faces, index, rows, cols)
    left = np.flatnonzero(~lit.done.all(axis=1))
    lit.light(left, ~lit.done[left])
    return lit.value, lit.exact


class _Lit:
    """:func:`by_source`'s texels so far: ``value`` (n, S, 3) their light per source, ``exact``
    (n, S) where it was found exactly, ``done`` (n, S) where it is settled (exactly or between
    anchors)."""

    def __init__(self, split, n):
        self.split = split
        v = split(np.zeros(0, np.int64), None)            # no texel: the sources' count and shape
        self.value = np.zeros((n,) + v.shape[1:])
        self.exact = np.zeros(self.value.shape[:2], bool)
        self.done = np.zeros(self.value.shape[:2], bool)

    def light(self, ids, need=None):
        """Light texels ``ids`` exactly in the sources ``need`` (len(ids), S) bool (None: all)
        they are not lit in yet, one call per set of sources."""
        if not ids.size:
            return
        need = ~self.exact[ids] if need is None else need & ~self.exact[ids]
        sets, of = np.unique(need, axis=0, return_inverse=True)
        for k, which in enumerate(sets):
            if not which.any():
                continue
            sel, src = ids[of.ravel() == k, None], np.flatnonzero(which)[None]
            self.value[sel, src] = self.split(sel[:, 0], None, None if which.all() else which)[:, which]
            self.exact[sel, src] = self.done[sel, src] = True


def from_inside(value, done, inside, faces, covered):
    """:func:`_rim` on the ``covered`` (H, W) texels' ``value`` (n, S, k) and ``done`` (n, S)
    (updated in place): a texel not done whose centre lies outside its triangle takes the
    mean of its 8 neighbours inside on its face (``inside``, ``faces`` (n,)) that are."""
    index = np.full(covered.shape, -1, np.int64)
    index[covered] = np.arange(int(covered.sum()))
    _rim(value, done, inside, faces, index, *np.nonzero(covered))


def _rim(value, done, inside, faces, index, rows, cols):
    """Texels not ``done`` (n, S) in a source whose centre lies outside their triangle (an
    island's rim, read clamped onto it) take that source's mean over their 8 neighbours inside
    on the same face, as Cycles' bake margin extends an island from its texels; ``value`` and
    ``done`` updated in place."""
    rim = np.flatnonzero(~done.all(axis=1) & ~inside)
    if rim.size == 0:
        return
    H, W = index.shape
    total = np.zeros((rim.size,) + value.shape[1:])
    count = np.zeros((rim.size, value.shape[1]))
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            r, c = rows[rim] + dr, cols[rim] + dc
            nb = np.full(rim.size, -1, np.int64)
            ok = (r >= 0) & (r < H) & (c >= 0) & (c < W) & ((dr != 0) | (dc != 0))
            nb[ok] = index[r[ok], c[ok]]
            ok = nb >= 0
            ok[ok] = inside[nb[ok]] & (faces[nb[ok]] == faces[rim[ok]])
            use = ok[:, None] & done[np.maximum(nb, 0)]                          # (r, S)
            total += np.where(use[..., None], value[np.maximum(nb, 0)], 0.0)
            count += use
    got = (count > 0) & ~done[rim]
    r, k = np.nonzero(got)
    value[rim[r], k] = total[r, k] / count[r, k][:, None]
    done[rim[r], k] = True


def _facing(faces, shading, ids):
    """The ``facing`` of points ``ids``' direct light: their face normals (the world's light only
    from directions in front of the face, as Cycles' diffuse closure drops what it samples behind
    it), or None where every shading normal is its face's (no direction to leave out)."""
    f, n = faces[ids], shading[ids]
    return None if np.array_equal(f, n) else f


def as_cycles(split, pts, nrm, shading, low, probed, lift=None):
    """``split(ids, samples, which, **shared)`` (``shared``: the world's ``split`` and ``part``,
    passed on) of the texels at ``pts`` (n, 3) with face normals ``nrm``
    and shading normals ``shading`` as Cycles' bake lights them: the world only from in front of
    the face (:func:`_facing`); where the shading normal leans off the face, a lamp below the
    face's plane by rays from ``low`` (n, 3) (Cycles' lifted start, :func:`.lift.lift`; None:
    from the texel as the rest), as a leaning vertex corner (:mod:`.crease`): a thin bevel's
    texel sees a sun below its plane past the bevel's edge; and no lamp nor emitter (the
    ``probed`` (S,) sources; None: no source is left out) where the shading normal turns away
    from the face (measured on a lone quad whose normals lean 95 or 120 degrees off it: a sun
    lights it from no direction, the world from those in front of it). ``lift`` (n,) or None:
    where a face covers a texel's point, how far off it along ``nrm`` its rays start (NaN
    elsewhere: a ray offset along the shading normal; :mod:`.texel_cover`)."""
    away = np.einsum("ij,ij->i", shading, nrm) < 0

    def lit(ids, samples, which=None, **shared):
        facing = _facing(nrm, shading, ids)
        x = pts[ids]
        up = None if lift is None else lift[ids]
        if up is not None and np.isfinite(up).any():      # covered: from Cycles' start, no offset
            x = x + np.where(np.isfinite(up), up, 0.0)[:, None] * nrm[ids]
            shared = dict(shared, eps=np.where(np.isfinite(up), 0.0, np.nan))
        D = split(x, shading[ids], samples, which, facing,
                  None if low is None or facing is None else low[ids], **shared)
        off = away[ids]
        if off.any() and probed is not None:
            D[np.ix_(off, np.asarray(probed, bool))] = 0.0
        return D
    return lit
