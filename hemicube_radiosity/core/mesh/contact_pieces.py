"""The elements cut along contacts put back together: the pieces' corners as shared vertices.

The last step of :func:`.contact.cut_along_contacts`: each cut element's pieces (convex
polygons, each tagged with the side of every contact line that parted or touched it) become
quads and triangles of one :class:`.patches.PatchSet`, a corner on a contact line a vertex of
its own side of it (a seam), every other corner the element's own vertex or one shared with its
neighbours' pieces. Every corner at once: a loop over them was a third of a game level's cut.
"""
from __future__ import annotations

import numpy as np

from .contact_lines import row_dots
from .patches import PatchSet, compact, poly_geometry
from ..util.unique import run_positions, unique_rows

__all__ = ["assemble_pieces"]


def assemble_pieces(elements: PatchSet, pieces, lines, eps) -> PatchSet:
    """The PatchSet of ``elements`` with each element of ``pieces`` ({element: [(polygon (k, 3),
    tags)]}, tags ((line, side), ...) with side +-1) replaced by its pieces, fanned into quads
    and triangles, in element order. ``lines``: per line (cutter (H,), start a (H, 3), in-plane
    normal m (H, 3), tolerance (H,), direction d (H, 3), length (H,)), world units.

    A corner on a line of its tags (within its tolerance across it, inside its ends: at an end
    the surface stops and the light goes round it, a block's corner does not part the floor) is
    a vertex of its side only, and of its plane (a cut across a box's edge leaves its two faces
    apart, as the box's own corners are): one vertex per object, place (``eps``), set of (cutter,
    side) and rounded normal, numbered in the order first met. Other corners take the element's
    vertex within ``eps`` of them, or such a vertex of their own."""
    N = len(elements)
    q = max(eps, 1e-300)
    cut = np.array(sorted(pieces), np.int64)
    flat = [pc for e in cut.tolist() for pc in pieces[e]]
    k = np.array([len(p) for p, _ in flat], np.int64)                 # corners a piece
    pe = np.repeat(cut, [len(pieces[e]) for e in cut.tolist()])        # each piece's element
    x = np.concatenate([p for p, _ in flat]) if flat else np.zeros((0, 3))
    ce = pe[np.repeat(np.arange(len(flat)), k)]                        # each corner's element
    n_on, on_set = _lines_under(x, k, [t for _, t in flat], lines)
    ids, new_verts = _corner_ids(elements, x, ce, n_on, on_set, q)
    polys, parent = _fanned(ids, k, pe)
    whole = np.setdiff1d(np.arange(N), cut)
    parent = np.concatenate([whole, parent])
    polys = np.concatenate([elements.polys[whole].astype(np.int64), polys])
    o = np.argsort(parent, kind="stable")
    polys, parent = polys[o], parent[o]
    verts = np.concatenate([elements.verts, new_verts])
    centers, _, areas = poly_geometry(verts, polys)
    keep = areas > 0
    polys, parent, centers, areas = polys[keep], parent[keep], centers[keep], areas[keep]
    verts, polys = compact(verts, polys)
    return PatchSet(verts, polys, centers, elements.normals[parent], areas, elements.rho[parent],
                    elements.emission[parent], elements.owner[parent], elements.source_face[parent],
                    list(elements.object_names))


def _lines_under(x, k, tags, lines):
    """The lines each corner lies on, of its piece's tags: (n_on (C,) how many, on_set (C, w)
    their codes 2 * cutter + (side > 0), sorted, padded with -1). ``x`` (C, 3) the pieces'
    corners, ``k`` (P,) corners a piece, ``tags`` per piece ((line, side), ...), ``lines`` as
    :func:`assemble_pieces`'s."""
    nt = np.array([len(t) for t in tags], np.int64)                  # tags a piece
    tag_line = np.array([ln for t in tags for ln, _ in t], np.int64)
    tag_side = np.array([s for t in tags for _, s in t], np.int64)
    t0 = np.r_[0, np.cumsum(nt)]
    cp = np.repeat(np.arange(len(k)), k)                             # each corner's piece
    # every (corner, tag of its piece) pair: is the corner on that tag's line?
    per = nt[cp]
    pc = np.repeat(np.arange(len(x)), per)
    pt = np.repeat(t0[cp], per) + run_positions(per)
    g, a, m, tol, d, length = (np.asarray(v)[tag_line[pt]] for v in lines)
    rel = x[pc] - a
    t = row_dots(rel, d)
    on = (np.abs(row_dots(rel, m)) <= tol) & (tol < t) & (t < length - tol)
    pc, code = pc[on], g[on] * 2 + (tag_side[pt[on]] > 0)
    o = np.lexsort((code, pc))                                         # each corner's set, sorted
    pc, code = pc[o], code[o]
    n_on = np.bincount(pc, minlength=len(x))
    wide = max(int(n_on.max(initial=0)), 1)
    on_set = np.full((len(x), wide), -1, np.int64)
    on_set[pc, run_positions(n_on)] = code
    return n_on, on_set


def _corner_ids(elements, x, ce, n_on, on_set, q):
    """(ids (C,) each corner's vertex id, new vertices (M, 3) numbered from len(elements.verts)):
    a corner on no line takes its element ``ce`` 's vertex within ``q`` of it; the others share
    one new vertex per object, place, set of lines and rounded normal, in the order first met."""
    V = len(elements.verts)
    src = elements.polys[ce]
    near = np.all(np.abs(elements.verts[np.maximum(src, 0)] - x[:, None]) <= q, axis=2) & (src >= 0)
    own = (n_on == 0) & near.any(axis=1)
    ids = np.where(own, src[np.arange(len(x)), near.argmax(axis=1)], -1)
    new = np.flatnonzero(~own)
    if not len(new):
        return ids, np.zeros((0, 3), elements.verts.dtype)
    key = np.column_stack([elements.owner[ce[new]].astype(np.int64), np.round(x[new] / q).astype(np.int64),
                           n_on[new], on_set[new], np.round(elements.normals[ce[new]] * 1e3).astype(np.int64)])
    _, inv = unique_rows(key, return_inverse=True)
    first = np.full(inv.max() + 1, len(new), np.int64)
    np.minimum.at(first, inv, np.arange(len(new)))
    rank = np.empty(len(first), np.int64)
    by = np.argsort(first, kind="stable")
    rank[by] = np.arange(len(first))
    ids[new] = V + rank[inv]
    return ids, x[new[first[by]]]


def _fanned(ids, k, pe):
    """(polys (F, 4) int64, parent (F,) int64): each piece (``k`` corners, vertex ``ids``, of
    element ``pe``) as quads and triangles, repeated corners dropped; pieces left with fewer
    than three corners dropped."""
    polys, parent = [], []
    bounds = np.r_[0, np.cumsum(k)].tolist()
    id_list = ids.tolist()
    for p, e in enumerate(pe.tolist()):
        c = _dedupe(id_list[bounds[p]:bounds[p + 1]])
        if len(c) < 3:
            continue
        for tri in _fan(c):
            polys.append(tri + [-1] * (4 - len(tri)))
            parent.append(e)
    return np.array(polys, np.int64).reshape(-1, 4), np.array(parent, np.int64)


def _dedupe(ids):
    out = []
    for i in ids:
        if not out or out[-1] != i:
            out.append(i)
    while len(out) > 1 and out[0] == out[-1]:
        out.pop()
    return out


def _fan(ids):
    """A convex polygon's corner ids as quads and triangles (<= 4 corners: itself)."""
    if len(ids) <= 4:
        return [list(ids)]
    out = []
    i = 1
    while i + 2 < len(ids):
        out.append([ids[0], ids[i], ids[i + 1], ids[i + 2]])
        i += 2
    if i + 1 < len(ids):
        out.append([ids[0], ids[i], ids[i + 1]])
    return out
