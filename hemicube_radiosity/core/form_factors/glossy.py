"""Extended form factors: light mirrored by glossy patches, with its direction (Embree).

A metal floor reflects no diffuse light, but a wall sees the ceiling and the lamp in it. The
paper's solve knows one reflectance per patch, spread as a Lambertian; a glossy surface's light
keeps its direction. After Wallace's and Sillion's two-pass methods, the light that patch k
sends to patch i by way of a glossy patch j is one more form factor:

    F^s_ik = sum_j g_j (A_j / A_i) P_j(k, i)

with g_j (3,) the glossy albedo of j (``MeshInput.face_glossy``, Cycles' at normal incidence)
and P_j(k, i) the share of the cosine-weighted rays from points on j whose ray along w meets
the front of i while the ray along w's reflection about j's normal meets the front of k. For
a mirror P_j is symmetric (w and its reflection are both cosine-distributed), and both ways of
every sample are kept with half the weight each. Then A_i F^s_ik = A_k F^s_ki (reciprocity) and
sum_k F^s_ik = g_j F_ij for a receiver that sees only j (a perfect mirror hands on what it
sees), which ``tests/core/test_glossy.py`` checks against closed forms. ``B_i = E_i + rho_i
(F B + F^s B)_i``: the sum stays linear and sparse, and depends on geometry only (g is applied
when it is read, :meth:`Specular.matrix`), so a relight reuses it.

A ray whose reflection finds no surface sees the world in the mirror: ``sky`` weights, per
receiver, as F's sky fractions. Light mirrored twice (a metal wall seen in a metal floor) is
not followed: a ray along w that lands on a glossy patch counts its diffuse part only (F's).

Rays per glossy patch: ``rays`` (a jittered grid of points on the patch, paired at random with
a jittered grid of cosine directions). Deterministic for a seed: each patch its own stream.
"""
from __future__ import annotations

from contextlib import closing
from dataclasses import dataclass, replace

import numpy as np

from ..rays import embree_scene, import_embreex, ray_offsets
from ..runtime.parallel import ordered_map, resolve_workers
from ..util.geometry import bilinear, tangent_frames
from ..util.sampling import cosine_directions, stratified_unit_square
from ..runtime.stored import storable
from ..util.sparse import CSR
from ..util.unique import unique_ints

__all__ = ["Specular", "bounded_by_view", "specular_transport", "GLOSSY_MIN"]

#: Glossy albedo (any band) from which a patch's mirrored light is followed with its direction;
#: below it, it is spread as diffuse light (:mod:`..mesh.specular`): Blender's default material
#: (0.037) spreads, a metal (0.8) or a lacquer mirrors.
GLOSSY_MIN = 0.1

#: Rays per ``scene.intersect`` call (two per sample).
SAMPLES_PER_BATCH = 1 << 17


@storable
@dataclass
class Specular:
    """What glossy patches hand on, per (receiver, source, glossy patch), geometry only.

    rows:   (E,) int64 receiving unknown i (a patch, or its cluster).
    cols:   (E,) int64 unknown k whose light arrives by way of the glossy patch.
    via:    (E,) int64 glossy patch j (a patch id, not a cluster).
    weight: (E,) float64 (A_j / A_i) P_j(k, i): times g_j it is F^s_ik's part through j.
    sky_rows, sky_via, sky_weight: the same for rays whose reflection finds no surface
            (receiver, glossy patch, (A_j / A_i) share).
    n:      the number of unknowns (F^s is n x n).
    rays:   rays per glossy patch; ``glossy`` (G,) the glossy patches that cast them.
    """

    rows: np.ndarray
    cols: np.ndarray
    via: np.ndarray
    weight: np.ndarray
    sky_rows: np.ndarray
    sky_via: np.ndarray
    sky_weight: np.ndarray
    n: int
    rays: int
    glossy: np.ndarray

    def matrix(self, g, band=None) -> CSR:
        """F^s (n, n) for glossy albedos ``g`` (N, 3) per patch: band ``band`` (0..2), or their
        least (None)."""
        gv = np.asarray(g, dtype=np.float64)
        gj = gv.min(axis=1) if band is None else gv[:, band]
        return CSR.from_coo(self.rows, self.cols, self.weight * gj[self.via], (self.n, self.n),
                            {"method": "glossy", "rays": self.rays})

    def apply(self, g, B) -> np.ndarray:
        """(n, 3) F^s_b B_b per band b, for glossy albedos ``g`` (N, 3) per patch and B (n, 3)."""
        B = np.asarray(B, dtype=np.float64)
        gv = np.asarray(g, dtype=np.float64)
        out = np.zeros((self.n, B.shape[1]))
        for b in range(B.shape[1]):
            out[:, b] = np.bincount(self.rows, weights=self.weight * gv[self.via, b] * B[self.cols, b],
                                    minlength=self.n)
        return out

    def sky(self, g) -> np.ndarray:
        """(n, 3) per receiver the share of its hemisphere that sees the world in a glossy patch,
        times that patch's albedo (F's ``sky`` for the mirrored world)."""
        gv = np.asarray(g, dtype=np.float64)
        return np.stack([np.bincount(self.sky_rows, weights=self.sky_weight * gv[self.sky_via, b],
                                     minlength=self.n) for b in range(gv.shape[1])], 1)

    def key(self) -> bytes:
        return self.glossy.tobytes() + str(self.rays).encode()


def patch_points(corners, u) -> np.ndarray:
    """(B, K, 3) points on patches with ``corners`` (B, 4, 3) (a triangle repeats its third)
    at unit-square points ``u`` (B, K, 2): bilinear on a quad, the square folded onto a
    triangle (uniform by area on a triangle and a parallelogram)."""
    s, t = u[..., 0:1], u[..., 1:2]
    c0, c1, c2 = (corners[:, None, i] for i in range(3))
    tri = np.all(corners[:, 3] == corners[:, 2], axis=1)[:, None, None]
    quad = bilinear(corners[:, None], s, t)
    fold = s + t > 1                      # the square's far half folded onto the near one
    a, b = np.where(fold, 1 - s, s), np.where(fold, 1 - t, t)
    triangle = c0 + a * (c1 - c0) + b * (c2 - c0)
    return np.where(tri, triangle, quad)


def specular_transport(patches, glossy, rays=1024, *, seed=0, clusters=None, workers=1,
                       cancelled=None) -> Specular:
    """The :class:`Specular` transport of the glossy patches ``glossy`` (G,) int of ``patches``
    (a :class:`..mesh.patches.PatchSet`): ``rays`` samples per glossy unknown (a cluster's
    glossy patches share them by area, :func:`_sample_points`; each patch alone without
    ``clusters``), each a point and a cosine-distributed direction w, cast along w and along
    its mirror image. Entries are over the unknowns: ``clusters`` (a hit on a patch counts for
    its cluster) or the patches. So the rays follow the unknowns, not the modelling: a chair
    of 40,000 lacquered faces in a few clusters casts a few thousand samples, not 40 million
    (bitterli_breakfast_room's glossy faces took 264 s and 7.4 GB). ``workers``: threads
    casting batches (the same result for any count). Raises :class:`..rays.EmbreeUnavailable`
    without embreex."""
    import_embreex()
    glossy = np.asarray(glossy, dtype=np.int64)
    k = int(rays)
    scene = embree_scene(patches)
    column = None if clusters is None else np.asarray(clusters.of, np.int64)
    n = len(patches) if clusters is None else len(clusters)
    areas = np.asarray(patches.areas if clusters is None else clusters.areas, dtype=np.float64)
    eps = ray_offsets(patches)
    corners = patches.corners()
    members, bounds = _by_unknown(glossy, column)        # each group its samples, by area
    per = max(1, SAMPLES_PER_BATCH // k)
    angles = np.random.default_rng([seed, 0x9105]).uniform(0, 2 * np.pi, len(patches))

    def cast(batch):
        jj, pid, dirs, group_area = _cast_batch(scene, patches, corners, members, bounds, batch,
                                                k, seed, angles, eps)
        return _entries(patches, column, areas, jj, pid, dirs, np.repeat(group_area, k) / k, n)

    parts, skies = [], []
    if glossy.size:
        scene.intersect(patches.centers[glossy[:1]], patches.normals[glossy[:1]])   # commit before threads
    groups = len(bounds) - 1
    batches = (np.arange(s, min(s + per, groups)) for s in range(0, groups, per))
    with closing(ordered_map(cast, batches, resolve_workers(workers))) as results:
        for part, sky in results:
            if cancelled is not None and cancelled():
                from ..runtime.progress import Cancelled
                raise Cancelled("cancelled")
            parts.append(part)
            skies.append(sky)
    rows, cols, via, wt = _merge(parts, n, len(patches))
    srows, _, svia, swt = _merge(skies, n, len(patches))
    return Specular(rows, cols, via, wt, srows, svia, swt, n, k, glossy)


def _cast_batch(scene, patches, corners, members, bounds, batch, k, seed, angles, eps):
    """Cast the ``k`` samples of each group of glossy patches in ``batch`` (B,) along their
    cosine direction w and its mirror image. Returns (jj (S,) the patch of each sample, S = B k;
    pid (2 S,) the patch hit along w then along the mirror, -1 for none; dirs (2 S, 3) those
    directions; group_area (B,) each group's area). A group's stream is its first glossy
    patch's (one patch alone: as it always was)."""
    rngs = [np.random.default_rng([seed, 0x9105, int(members[bounds[g]])]) for g in batch]
    u = np.stack([stratified_unit_square(r, 1, k)[0] for r in rngs])          # (B,k,2) points
    v = np.stack([stratified_unit_square(r, 1, k)[0][r.permutation(k)] for r in rngs])
    j, x, group_area = _sample_points(patches, corners, members, bounds, batch, u)   # (B,k), (B,k,3)
    nrm = patches.normals[j]                                                  # (B,k,3)
    frames = tangent_frames(nrm.reshape(-1, 3), angles[j].reshape(-1)).reshape(*j.shape, 3, 3)
    d = np.einsum("bkc,bkcj->bkj", cosine_directions(v), frames)              # (B,k,3)
    m = 2.0 * np.einsum("bkj,bkj->bk", d, nrm)[..., None] * nrm - d           # mirrored
    o = (x + eps[j][..., None] * nrm).reshape(-1, 3)
    dirs = np.concatenate([d.reshape(-1, 3), m.reshape(-1, 3)])
    pid, _ = scene.intersect(np.concatenate([o, o]), dirs)
    return j.reshape(-1), np.asarray(pid, np.int64), dirs, group_area


def _entries(patches, column, areas, jj, pid, dirs, w, n):
    """The summed (surface, sky) transport entries of one batch of :func:`_cast_batch`'s
    samples, ``w`` (S,) each sample's share of its group's area: a sample whose two ways both
    reach a front face (not its own patch) links them both ways, half the weight each; one way
    on a surface and the other on nothing lets that receiver see the world in the mirror."""
    hit = pid >= 0
    ok = hit.copy()
    ok[hit] = np.einsum("ij,ij->i", dirs[hit], patches.normals[pid[hit]]) < 0   # fronts only
    ok &= pid != np.tile(jj, 2)
    col = np.where(ok, pid if column is None else column[np.maximum(pid, 0)], -1)
    S = len(jj)
    a, b = col[:S], col[S:]                # along w, along its mirror image
    both = (a >= 0) & (b >= 0)
    # both ways of each sample, half the weight each: (receiver a, source b) and (b, a)
    rows = np.concatenate([a[both], b[both]])
    cols = np.concatenate([b[both], a[both]])
    via = np.concatenate([jj[both], jj[both]])
    wt = 0.5 * np.concatenate([w[both], w[both]]) / areas[rows]
    # one way found a surface, the other nothing: the receiver sees the world in the mirror
    ra = np.concatenate([a[(a >= 0) & ~hit[S:]], b[(b >= 0) & ~hit[:S]]])
    sv = np.concatenate([jj[(a >= 0) & ~hit[S:]], jj[(b >= 0) & ~hit[:S]]])
    sw = 0.5 * np.concatenate([w[(a >= 0) & ~hit[S:]], w[(b >= 0) & ~hit[:S]]]) / areas[ra]
    return (_summed(rows, cols, via, wt, n, len(patches)),
            _summed(ra, np.zeros_like(ra), sv, sw, n, len(patches)))


def _by_unknown(glossy, column):
    """(members (G,), bounds (U + 1,)): the glossy patches ``glossy`` grouped by their unknown
    (``column`` (N,), or each patch its own where None), in their order within each group:
    group g is ``members[bounds[g]:bounds[g + 1]]``, its first patch the first it had in
    ``glossy``."""
    inv = unique_ints(glossy if column is None else column[glossy], return_inverse=True)[1].reshape(-1)
    bounds = np.concatenate([[0], np.cumsum(np.bincount(inv))]).astype(np.int64)
    return glossy[np.argsort(inv, kind="stable")], bounds


def _sample_points(patches, corners, members, bounds, batch, u):
    """(patch (B, k), point (B, k, 3), group area (B,)) of the samples ``u`` (B, k, 2) of the
    groups ``batch``: group g's glossy patches are ``members[bounds[g]:bounds[g + 1]]``; a
    sample's first coordinate picks a patch by area (the strata of a patch are its share of the
    square) and, rescaled into that patch's share, places the point on it with the second."""
    B, k = u.shape[:2]
    j = np.empty((B, k), np.int64)
    s = u[..., 0].copy()
    total = np.empty(B)
    for r, g in enumerate(batch):
        mine = members[bounds[g]:bounds[g + 1]]
        a = np.asarray(patches.areas, dtype=np.float64)[mine]
        total[r] = a.sum()
        if mine.size == 1:                    # one patch: the square as it is
            j[r] = mine[0]
            continue
        cdf = np.concatenate([[0.0], np.cumsum(a)]) / total[r]
        i = np.clip(np.searchsorted(cdf, s[r], side="right") - 1, 0, mine.size - 1)
        j[r] = mine[i]
        s[r] = np.clip((s[r] - cdf[i]) / np.maximum(cdf[i + 1] - cdf[i], 1e-300), 0.0, 1.0)
    x = patch_points(corners[j.reshape(-1)], np.stack([s, u[..., 1]], -1).reshape(-1, 1, 2))
    return j, x.reshape(B, k, 3), total


def _summed(rows, cols, via, w, n, N):
    """(rows, cols, via, weight) with equal (row, col, via) triples summed (sorted by them)."""
    if not len(rows):
        z = np.zeros(0, np.int64)
        return z, z, z, np.zeros(0)
    pair = np.asarray(rows, np.int64) * n + cols
    via = np.asarray(via, np.int64)
    if n * n * N < 2 ** 62:                  # one integer key: a hash-free sort of it
        uk, inv = unique_ints(pair * N + via, return_inverse=True)
        s = np.bincount(inv.reshape(-1), weights=w, minlength=uk.size)
        pair, via = uk // N, uk % N
        return pair // n, pair % n, via, s
    order = np.lexsort((via, pair))
    pair, via = pair[order], via[order]
    new = np.ones(len(pair), bool)
    new[1:] = (pair[1:] != pair[:-1]) | (via[1:] != via[:-1])
    starts = np.flatnonzero(new)
    s = np.add.reduceat(np.asarray(w, np.float64)[order], starts)
    return pair[starts] // n, pair[starts] % n, via[starts], s


def _merge(parts, n, N):
    if not parts:
        z = np.zeros(0, np.int64)
        return z, z, z, np.zeros(0)
    if len(parts) == 1:                      # one batch: summed already
        return parts[0]
    return _summed(*(np.concatenate([p[i] for p in parts]) for i in range(4)), n, N)


# --------------------------------------------------------------------------------------------
# The stages' parts: the transport made (form factors), the mirrored emitters and world
# (direct light), the solve's matrix (solve)


def specular_stage(ctx) -> None:
    """Fill ``ctx.glossy`` (N, 3) per patch (None: no face mirrors) and ``ctx.specular`` (its
    :class:`Specular`, cached with the geometry, the glossy patches and the rays)."""
    from ..mesh.specular import patch_glossy
    from ..runtime.cache import cache_key, cached, geometry_key

    ctx.glossy = ctx.specular = None
    g = patch_glossy(ctx.meshes, ctx.patches) if ctx.settings.specular_bounce else None
    if g is None:
        return
    glossy = np.flatnonzero(g.max(axis=1) > 0)
    s = ctx.settings
    grouping = b"" if ctx.clusters is None else np.ascontiguousarray(ctx.clusters.of).tobytes()
    key = cache_key(geometry_key(ctx.patches) + grouping + glossy.tobytes(),
                    ("specular", int(s.specular_rays), int(s.rotate_seed or 0)))
    ctx.say(0.0, f"light mirrored by {glossy.size} glossy patches")
    ctx.glossy = g
    ctx.specular = bounded_by_view(cached(ctx.cache, key, lambda: specular_transport(
        ctx.patches, glossy, s.specular_rays, seed=int(s.rotate_seed or 0), clusters=ctx.clusters,
        workers=s.workers, cancelled=ctx.cancelled)), ctx.form_factors,
        None if ctx.clusters is None else ctx.clusters.of)


def bounded_by_view(spec, F, of=None) -> Specular:
    """``spec`` with each receiver's entries scaled down, where they pass it, to what the
    receiver sees of the glossy patches: sum_k (A_j / A_i) P_j(k, i) plus its sky part is an
    estimate of F_ij from j's rays (module docstring), exact in expectation, but a receiver
    much smaller than the mirror is met by few of its rays, each weighted A_j / A_i: one hit
    on a sliver gave a row of F + F^s a sum of 2.2 (rho times it 1.76: a real room's solve
    refused). F (the unknowns' form factors, the receiver's own hemi-cube) bounds the row's
    sum over the glossy patches (a row, not each pair: a pair met by a few rays is noisy both
    ways, and capping each would lose light on average); ``of`` (N,) each patch's unknown
    (its cluster) or None."""
    n = spec.n
    via = np.concatenate([spec.via, spec.sky_via])
    if not via.size:
        return spec
    rows = np.concatenate([spec.rows, spec.sky_rows])
    est = np.bincount(rows, weights=np.concatenate([spec.weight, spec.sky_weight]), minlength=n)
    cols = np.zeros(F.shape[1], bool)
    cols[spec.glossy if of is None else np.asarray(of, np.int64)[spec.glossy]] = True
    hit = cols[F.indices]
    view = np.bincount(F.row_ids()[hit], weights=np.asarray(F.data, np.float64)[hit], minlength=n)
    scale = np.where(est > view, view / np.where(est > 0, est, 1.0), 1.0)
    if np.all(scale == 1.0):
        return spec
    return replace(spec, weight=spec.weight * scale[spec.rows], sky_weight=spec.sky_weight * scale[spec.sky_rows])


def lamps_in_mirrors(ctx) -> np.ndarray | None:
    """(K, 3) radiance arriving at the unknowns from the lamps' light (points, spots, area lights,
    suns, an environment map) that glossy patches reflect, spread as diffuse light: F (g D_lamps)
    with D_lamps the lamps' light arriving at each glossy patch's centre. A lamp is a point or a
    direction the rays of :func:`specular_transport` never meet, so its mirrored light keeps its
    energy, not its direction (:mod:`..mesh.specular`'s spread). None without a glossy patch
    or a lamp."""
    if ctx.specular is None or not ctx.lights:
        return None
    p, s, gl = ctx.patches, ctx.settings, ctx.specular.glossy
    if ctx.direct is None:                     # the paper's path: the lamps at the patch centres
        D = np.asarray(ctx.irradiance, dtype=np.float64)[gl] / np.pi
    else:
        from ..light.lamp_cache import lamp_irradiance
        x, n = p.centers[gl], p.normals[gl]
        D = lamp_irradiance(p, ctx.lights, ctx.cache, points=x, normals=n, eps=ctx.direct.offsets(x, n),
                            samples=s.light_samples, seed=s.light_seed, cancelled=ctx.cancelled,
                            workers=s.workers) / np.pi
    L = np.zeros((len(p), 3))
    L[gl] = ctx.glossy[gl] * np.maximum(D, 0.0)
    return ctx.form_factors.matvec(ctx.to_unknowns(L))


def mirrored_source(ctx, emitted, world) -> np.ndarray | None:
    """(K, 3) what the unknowns reflect of the light ``emitted`` (K, 3) by the unknowns and of
    the ``world`` (3,) radiance or None, arriving by way of a glossy patch: rho F^s E + rho
    sky^s L_world, plus the lamps' (``ctx.lamps_mirrored``, :func:`lamps_in_mirrors`); None
    without a glossy patch. Fills ``ctx.lamps_mirrored``."""
    u = ctx.unknowns
    ctx.lamps_mirrored = None
    if ctx.specular is None:
        return None
    arriving = ctx.specular.apply(ctx.glossy, emitted)
    ctx.lamps_mirrored = lamps_in_mirrors(ctx)
    if ctx.lamps_mirrored is not None:
        arriving += ctx.lamps_mirrored
    if world is not None and np.any(np.asarray(world) > 0):
        arriving += ctx.specular.sky(ctx.glossy) * np.asarray(world, dtype=np.float64)[None, :]
    return u.rho * arriving


def mirrored_arrival(ctx) -> np.ndarray:
    """(K, 3) radiance arriving at the unknowns by way of a glossy patch once the solve is done:
    F^s B (B with the emitters' light) plus the world seen in a mirror and the lamps' light off
    mirrors (:func:`lamps_in_mirrors`)."""
    B = np.asarray(ctx.solution.B, dtype=np.float64)
    out = ctx.specular.apply(ctx.glossy, B)
    if ctx.lamps_mirrored is not None:
        out += ctx.lamps_mirrored
    world = ctx.direct.world if ctx.direct is not None else ctx.world
    if world is not None and np.any(np.asarray(world) > 0):
        out += ctx.specular.sky(ctx.glossy) * np.asarray(world, dtype=np.float64)[None, :]
    return out


def solve_matrix(ctx, F):
    """(F + F^s, d, correction) for the solve, or (F, None, None) without a glossy patch.

    F^s at the least of the bands' albedos is added to F (one matrix, as the solvers take);
    ``correction(B) -> (K, 3)`` is what the bands' own albedos add to rho F^s B beside it, never
    negative (None where every glossy patch is grey). ``d`` (K,) scales the unknowns for the solvers: a glossy
    unknown's radiosity (its diffuse part) is solved for as B / d, d = rho / (rho + g) (its
    largest band; 0 for a metal, whose B is 0, or 1 - g for an emitting one on the paper's
    direct path). F + F^s counts a direction that meets a glossy
    patch twice, in F for its diffuse part and in F^s for its mirror image, so rho times its row
    sum may pass 1 (a wall at a metal floor's edge sees half its hemisphere in the floor: 0.8 x
    (1 + 0.8 x 0.5) > 1) although the light it hands on does not grow: in the scaled unknowns
    each such direction counts d + g <= 1 (as rho + g <= 1), and the solvers' test of
    convergence (rho times the row sum below 1) holds."""
    if ctx.specular is None:
        return F, None, None
    Fs = ctx.specular.matrix(ctx.glossy)
    both = CSR.from_coo(np.concatenate([F.row_ids(), Fs.row_ids()]), np.concatenate([F.indices, Fs.indices]),
                        np.concatenate([F.data.astype(np.float64), Fs.data.astype(np.float64)]), F.shape, F.meta)
    both.sky = F.sky
    u = ctx.unknowns
    rho, gu = np.asarray(u.rho, dtype=np.float64), ctx.to_unknowns(ctx.glossy)
    total = rho + gu
    d = np.where(total > 0, rho / np.where(total > 0, total, 1.0), 0.0).max(axis=1)
    d = np.where(gu.max(axis=1) > 0, d, 1.0)
    if ctx.direct is None:       # the paper's path: a metal emitter's B is its emission, not 0
        lit = (d <= 0) & (np.asarray(u.emission).max(axis=1) > 0)
        d = np.where(lit, 1.0 - gu.max(axis=1), d)
    g = ctx.glossy
    grey = np.repeat(g.min(axis=1, keepdims=True), g.shape[1], axis=1)
    if np.allclose(g, grey, rtol=0, atol=1e-6):
        return both, d, None
    return both, d, lambda B: rho * ctx.specular.apply(g - grey, np.maximum(B, 0.0))
