"""The share of a vertex's gathered light a corner takes where its shading normal leans off its
triangle (core/output/above.py): what the gather's hits read from above the corner's plane."""
import numpy as np

from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.output.above import above_shares


class _Ctx:
    def __init__(self, H):
        self.gather_rays = lambda hits=True: (None, H)


def _two_plates():
    """Two 1 m plates, one at z = +1 and one at z = -1, as two elements of four vertices each."""
    quad = [(0, 0), (1, 0), (1, 1), (0, 1)]
    m = MeshInput.from_faces([(x, y, 1.0) for x, y in quad] + [(x, y, -1.0) for x, y in quad],
                             [(0, 1, 2, 3), (4, 7, 6, 5)], name="plates")
    return build_patches([m], 10.0)


def test_the_share_is_what_the_hits_above_the_corner_s_plane_read():
    E = _two_plates()
    assert len(E) == 2
    up = int(np.argmax(E.centers[:, 2]))
    read = np.where(E.verts[:, 2:3] > 0, 1.0, 3.0) * np.ones((1, 3))   # the lower plate 3x brighter
    xv = np.zeros((len(E.verts), 3))                                     # every vertex at the origin
    v = 0                                                                # the corner's vertex: point 0
    hits = [(v, up, 0.5, 0.5, 1.0)] * 4 + [(v, 1 - up, 0.25, 0.75, -1.0)] * 4 + [(1, up, 0.5, 0.5, 1.0)] * 3
    H = np.array(sorted(hits), dtype=np.float32)
    p = np.flatnonzero((E.polys == v).any(axis=1))[:1]
    c = np.array([int(np.flatnonzero(E.polys[p[0]] == v)[0])])
    for geo, want in (((0.0, 0.0, 1.0), 0.25), ((0.0, 0.0, -1.0), 0.75)):
        got = above_shares(_Ctx(H), E, p, c, np.array([geo]), xv, read)
        np.testing.assert_allclose(got, want, rtol=1e-6)
    # hits carrying weights of their own (shared rays, see-through faces): weighted
    W = np.column_stack([H, np.where(H[:, 4] > 0, 2.0, 1.0)]).astype(np.float32)
    got = above_shares(_Ctx(W), E, p, c, np.array([(0.0, 0.0, 1.0)]), xv, read)
    np.testing.assert_allclose(got, 8 / (8 + 12), rtol=1e-6)
    # no gather (no Embree, no rays) or no hit: not known
    assert np.isnan(above_shares(_Ctx(None), E, p, c, np.array([(0.0, 0.0, 1.0)]), xv, read)).all()
    none = H[H[:, 0] != v]
    assert np.isnan(above_shares(_Ctx(none), E, p, c, np.array([(0.0, 0.0, 1.0)]), xv, read)).all()


def test_corners_that_share_a_vertex_read_its_hits_each_against_its_own_plane():
    E = _two_plates()
    up = int(np.argmax(E.centers[:, 2]))
    read = np.where(E.verts[:, 2:3] > 0, 1.0, 3.0) * np.ones((1, 3))
    xv = np.zeros((len(E.verts), 3))
    a, b = 0, int(E.polys[1 - up, 0])                # a vertex of each plate
    hits = [(a, up, 0.5, 0.5, 1.0)] * 4 + [(a, 1 - up, 0.25, 0.75, -1.0)] * 4 \
        + [(b, up, 0.5, 0.5, 1.0)] * 1 + [(b, 1 - up, 0.5, 0.5, -1.0)] * 2
    H = np.array(sorted(hits), dtype=np.float32)
    pa = int(np.flatnonzero((E.polys == a).any(axis=1))[0])
    pb = int(np.flatnonzero((E.polys == b).any(axis=1))[0])
    ca, cb = (int(np.flatnonzero(E.polys[q] == x)[0]) for q, x in ((pa, a), (pb, b)))
    # vertex a's hits read by three corners (two planes), b's by one, in a mixed order
    p = np.array([pa, pb, pa, pa])
    c = np.array([ca, cb, ca, ca])
    geo = np.array([(0, 0, 1.0), (0, 0, 1.0), (0, 0, -1.0), (0, 0, 1.0)])
    got = above_shares(_Ctx(H), E, p, c, geo, xv, read)
    # a: 4 hits reading 1 above z = 0, 4 reading 3 below; b: 1 reading 1 above, 2 reading 3 below
    np.testing.assert_allclose(got, [4 / 16, 1 / 7, 12 / 16, 4 / 16], rtol=1e-6)


def test_a_relight_reads_the_kept_sums_and_an_edit_misses_them():
    """With a cache the hits' reading and their spread over the corners are kept (a relight reads
    no hit): a brighter light gives the shares of a call without a cache, bit for bit; moved
    points (an edit) give the moved points' shares, not the kept ones (truth: the closed form of
    the test above, 4 hits reading 1 above, 4 reading 3 below)."""
    from hemicube_radiosity.core.runtime.cache import FormFactorCache

    E = _two_plates()
    up = int(np.argmax(E.centers[:, 2]))
    read = np.where(E.verts[:, 2:3] > 0, 1.0, 3.0) * np.ones((1, 3))
    v = 0
    hits = [(v, up, 0.5, 0.5, 1.0)] * 4 + [(v, 1 - up, 0.25, 0.75, -1.0)] * 4 + [(1, up, 0.5, 0.5, 1.0)] * 3
    H = np.array(sorted(hits), dtype=np.float32)
    p = np.flatnonzero((E.polys == v).any(axis=1))[:1]
    c = np.array([int(np.flatnonzero(E.polys[p[0]] == v)[0])])
    geo = np.array([(0.0, 0.0, 1.0)])
    ctx = _Ctx(H)
    ctx.cache, ctx.gather_key = FormFactorCache(), "g"
    xv = np.zeros((len(E.verts), 3))
    first = above_shares(ctx, E, p, c, geo, xv, read)
    np.testing.assert_allclose(first, 0.25, rtol=1e-6)
    n = len(ctx.cache._mem)
    relit = above_shares(ctx, E, p, c, geo, xv, 1.5 * read)
    np.testing.assert_array_equal(relit, above_shares(_Ctx(H), E, p, c, geo, xv, 1.5 * read))
    assert n >= 2 and len(ctx.cache._mem) == n           # kept (reading, sums); nothing new: found
    # the points moved to z = 2, above both plates: every hit is below the corner's plane
    moved = np.zeros((len(E.verts), 3)) + (0.0, 0.0, 2.0)
    got = above_shares(ctx, E, p, c, geo, moved, read)
    np.testing.assert_array_equal(got, above_shares(_Ctx(H), E, p, c, geo, moved, read))
    np.testing.assert_allclose(got, 0.0, atol=1e-12)
