"""Direct light at any points: :class:`DirectLight`, what the direct stage, the output stage and
the lightmaps ask for the light arriving straight from the emitting faces, the lamps and the
world (each apart, or summed), with its shadow rays' caches.

Units: radiance (W m^-2 sr^-1 per unit of colour); irradiance is pi * radiance.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..runtime.cache import array_key, cache_key, cached, geometry_key
from .emitters import emitter_transport, transport_product, transposed_transport
from .environment import RAYS_PER_SKY_RAY, EnvironmentLight
from .lamp_cache import lamp_irradiance, shadow_key as _shadow_key
from .lamps import SunLight
from .points import turned_around
from ..mesh.patches import PatchSet
from ..runtime.progress import Ticker
from ..rays import occluder, ray_offsets
from ..hemisphere import SKY_FIRST, sky_fraction
from ..runtime.cache import Memo, frozen
from ..util.colour import LUMA
from ..util.unique import unique_ints

__all__ = ["DirectLight", "turns_emitters"]

_OFFSETS = Memo(4)          # rays' start offsets per point array (:meth:`DirectLight.offsets`)


@dataclass
class DirectLight:
    """Exact direct light for one bake: emissive patches and lamps, evaluated at any points.

    ``emitters`` (M,) ids of emissive patches; ``samples`` shadow rays per point and unit;
    ``groups`` (M,) or None: emitting patches that shine as one unit, with ``samples`` rays
    spread over it (``settings.direct_samples``): the patches of one cluster (small faces
    grouped), or without clusters those cut from one flat input face of one emission
    (:func:`_face_groups`). None: each patch a unit of its own, with its face's
    ``direct_samples`` shared between the patches it was cut into, at least 2 each;
    ``lights`` core.light.lamps objects with ``light_samples`` / ``light_seed`` for their shadow rays.
    The emitters' part goes through a transport matrix that depends on geometry only, cached in
    ``cache``: a new emission strength or colour is a matrix product, no rays.
    """

    patches: PatchSet
    lights: list
    emitters: np.ndarray
    samples: int
    light_samples: int = 16
    light_seed: int = 0
    cancelled: object = None
    cache: object = None
    groups: np.ndarray | None = None
    two_sided: bool = False
    workers: int = 1                          # threads for the transport (settings.workers)
    world: np.ndarray | None = None           # (3,) constant world radiance, or None (black)
    sky_rays: int = 256                       # rays per point that look for the world
    _scene: object = field(default=None, repr=False)
    _emitted: object = field(default=None, repr=False)

    @classmethod
    def plan(cls, patches: PatchSet, settings, lights, cancelled=None, cache=None, clusters=None,
             world=None):
        """The exact direct light for ``settings``, or None when it is off or there is none.
        ``world`` (3,) radiance: the world's light is direct light too, seen where rays from a
        point find no surface (:meth:`world_at`)."""
        emitters = np.flatnonzero(patches.emitting())
        world = None if world is None or not np.any(np.asarray(world) > 0) else np.asarray(world, float)
        if settings.direct == "hemicube" or (emitters.size == 0 and not lights and world is None):
            return None
        samples, groups = settings.direct_samples, None
        if emitters.size and clusters is not None:
            groups = unique_ints(clusters.of[emitters], return_inverse=True)[1].reshape(-1)
            if isinstance(settings.patch_size, (int, float)) and settings.patch_size > 0:   # resolved
                groups = _whole_groups(patches, emitters, groups, 0.5 * float(settings.patch_size) ** 2)
        elif emitters.size:
            face = patches.owner[emitters].astype(np.int64) * (1 << 32) + patches.source_face[emitters]
            _, first, of_face, count = unique_ints(face, return_index=True, return_inverse=True,
                                                   return_counts=True)
            per_face = int(count.max())
            # the face's rays shared out, but at least 2 per patch (a 2 x 2 jittered grid): with
            # one ray a point sees each patch all lit or all dark, never in part, so a penumbra
            # is never found nor refined (:func:`.emitters.emitter_transport`) and a soft shadow
            # steps in as many levels as the face has patches (the Cornell box's light, cut
            # in 9, made the roughest part of its bake)
            budget = int(settings.direct_samples)
            samples = max(min(2, budget), -(-budget // per_face))
            groups = _face_groups(patches, emitters, first, of_face) if per_face > 1 else None
            if groups is not None:
                # a face shining as one: the rays its patches cast apart (the 2 x 2 grids: finer
                # patches ask for finer shadows), at most 4 x its budget
                grid = int(np.ceil(np.sqrt(samples))) ** 2
                samples = max(budget, min(per_face * grid, 4 * budget))
        # an environment map's directions per point: RAYS_PER_SKY_RAY x the bake's Sky Rays
        lights = [replace(li, rays=RAYS_PER_SKY_RAY * settings.sky_rays) if isinstance(li, EnvironmentLight)
                  else li for li in lights]
        return cls(patches, list(lights), emitters, samples, settings.light_samples,
                   settings.light_seed, cancelled, cache, groups, turns_emitters(settings),
                   workers=settings.workers, world=world, sky_rays=settings.sky_rays)

    def offsets(self, points, normals) -> np.ndarray:
        """(P,) how far rays from ``points`` start off their surfaces (:func:`.rays.ray_offsets`:
        their own objects', found by a probe ray), made once per point array and kept in the cache
        under the geometry and the points' values (a relight's normals are new arrays of the same
        values: it casts no probe ray)."""
        def make():
            key = cache_key(geometry_key(self.patches) + array_key(self.patches.owner) + array_key(points)
                            + array_key(normals), ("ray-offsets",))
            return cached(self.cache, key, lambda: ray_offsets(self.patches, points, normals))
        return _OFFSETS.of((self.patches.verts, points, normals), make)

    def _transport(self, points, normals, samples=None, eps=None):
        """The emitters' transport to ``points``: their fronts, plus their backs when two-sided
        (the same faces turned around, so the front-only tests and shadow-ray offsets apply).
        ``eps`` (P,): the rays' start offsets (default :meth:`offsets`)."""
        eps = self.offsets(points, normals) if eps is None else eps

        def transport(patches):
            return emitter_transport(patches, points, normals, self.emitters, scene=self.scene(),
                                     samples=samples or self.samples, ticker=Ticker(None, self.cancelled),
                                     refine=3 if samples is None else 0,
                                     groups=self.groups, workers=self.workers, eps=eps)
        T = transport(self.patches)
        return T + transport(turned_around(self.patches)) if self.two_sided else T

    def emitted(self) -> np.ndarray:
        """(M, 3) radiance of each column of the transport: per emitting patch, or the
        area-weighted mean of each group. Made once (read-only): every point set lit asks for it
        (a relight's dozen)."""
        if self._emitted is None:
            L = self.patches.emission[self.emitters]
            if self.groups is not None:
                a = self.patches.areas[self.emitters]
                G = int(self.groups.max()) + 1
                L = np.stack([np.bincount(self.groups, weights=a * L[:, k], minlength=G) for k in range(3)], 1) \
                    / np.bincount(self.groups, weights=a, minlength=G)[:, None]
            self._emitted = frozen(L)
        return self._emitted

    def _emitters_at(self, points, normals, where, samples=None, transposed=False, eps=None):
        """(P, units) the emitters' transport to ``points`` (cached: geometry only);
        ``transposed``: (units, P) float64 instead, as :func:`.emitters.transport_product` reads
        it fastest (cached beside it); ``eps`` (P,): the rays' start offsets (default
        :meth:`offsets`)."""
        samples = None if samples is None else min(samples, self.samples)
        key = None
        if self.cache is not None:   # the geometry and the points hashed once per array (a relight's are cached)
            grouped = b"" if self.groups is None else self.groups.tobytes()
            own = b"" if eps is None else array_key(np.asarray(eps, dtype=np.float64))
            key = cache_key(_shadow_key(self.patches) + self.emitters.tobytes() + grouped + array_key(points) + own,
                            ("direct", where, samples, self.two_sided))
        T = cached(self.cache if key else None, key, lambda: self._transport(points, normals, samples, eps))
        if not transposed:
            return T
        return cached(self.cache if key else None, key and key + "-t", lambda: transposed_transport(T), disk=False)

    def world_at(self, points, normals, where: str, eps=None, facing=None, split=1, part=None,
                 first=None) -> np.ndarray:
        """(P, 3) the world's radiance arriving at ``points``: ``world`` times the cosine-weighted
        fraction of the hemisphere where rays find no surface (:func:`.hemisphere.sky_fraction`,
        ``sky_rays`` per point; geometry only, cached). ``eps`` (P,): the rays' start offsets
        (default :meth:`offsets`); ``facing`` (P, 3), ``split``, ``part``: as :meth:`at`.
        ``first``: :func:`.hemisphere.sky_fraction`'s; None: :data:`.hemisphere.SKY_FIRST` for
        points lit one by one (no ``facing``, no ``split``), else 1."""
        if split > 1 and self.sky_rays % split:      # the pattern does not share out evenly
            split, part = 1, None
        own = b"" if eps is None else array_key(np.asarray(eps, dtype=np.float64))
        own += b"" if facing is None else array_key(np.asarray(facing, dtype=np.float64))
        own += b"" if part is None else array_key(np.asarray(part, dtype=np.int64))
        # points lit one by one (no ``facing``, no ``split``): a share of the rays first, the
        # rest where those are mixed (:data:`.hemisphere.SKY_FIRST`)
        if first is None:
            first = SKY_FIRST if facing is None and split == 1 else 1
        key = cache_key(_shadow_key(self.patches) + array_key(points) + own,
                        ("sky", where, self.sky_rays, split) + ((first,) if first > 1 else ()))
        eps = self.offsets(points, normals) if eps is None else eps
        f = cached(self.cache, key, lambda: sky_fraction(self.scene(), np.ascontiguousarray(points, dtype=np.float64),
                                                         normals, self.sky_rays, eps=eps, facing=facing,
                                                         workers=self.workers, split=split, part=part, first=first))
        return f[:, None] * self.world[None, :]

    def sources_at(self, points, normals, where: str, world: bool = True) -> np.ndarray:
        """(P, S) luminance arriving directly at ``points`` from each source apart, in
        :meth:`split_at`'s units (summed, :meth:`at`'s luminance): every emitting object (its
        faces together), every lamp, the world (not with ``world`` False: its rays are the
        costliest). A source's column scales with its
        strength and (its luminance) with its colour, so what depends only on each column's
        shape, not its scale, is the same after a relight."""
        cols = []
        if self.emitters.size:
            T = self._emitters_at(points, normals, where)
            Y = self.emitted() @ LUMA
            owner = _unit_owner(self)
            cols += [T[:, owner == o].astype(np.float64) @ Y[owner == o] for o in np.unique(owner)]
        for i, lamp in enumerate(self.lights):      # lamp i's own random stream, as split_at draws it
            cols.append(lamp_irradiance(self.patches, [lamp], self.cache, points=points, normals=normals,
                                        eps=self.offsets(points, normals), index=i,
                                        cancelled=self.cancelled, samples=self.light_samples,
                                        seed=self.light_seed, workers=self.workers) @ LUMA / np.pi)
        if self.world is not None and world:   # every ray: the columns' shapes decide (a refinement)
            cols.append(self.world_at(points, normals, where, first=1) @ LUMA)
        return np.stack(cols, axis=1) if cols else np.zeros((len(points), 0))

    def split_at(self, points, normals, where: str, samples=None, which=None, facing=None,
                 low=None, split=1, part=None, eps=None) -> np.ndarray:
        """(P, S, 3) radiance arriving directly at ``points`` from each source apart: every
        emitting object (its faces together), every lamp, the world, in that order; summed over
        the sources (and clamped at 0) it is :meth:`at`'s (to rounding). A source's column
        scales with its strength and colour, so what depends only on each column's shape, not
        its scale, is the same after a relight. ``samples``: fewer shadow rays per point for the
        emitters and lamps, as :meth:`at` takes it (the world's rays are ``sky_rays``);
        ``which`` (S,) bool or None: only those columns (the others 0); ``facing`` (P, 3) or
        None: the world's light only from directions on its side (Cycles' diffuse closure drops
        the directions it samples behind the face; a lamp's and an emitter's light is sampled on
        the source, whatever side: measured on a lone quad whose shading normal leans 60 degrees
        off it, a sun 11 degrees behind its face lights it by the cosine to that normal).
        ``low`` (P, 3) with ``facing``: the lamps' light is split at the plane of ``facing``,
        from above it by rays from the points, from below it by rays from ``low`` (where
        Cycles' shadow rays toward such a light start: :func:`..output.lift.lift`), as
        :mod:`..output.crease` lights a leaning corner. ``split``, ``part``: the world's rays
        shared out among runs of points whose mean is what is read, as :meth:`at`'s. ``eps``
        (P,) or None: how far the rays start off the points, NaN where :meth:`offsets` says (a
        lightmap's texel under a face nearer than that: :mod:`..output.texel_cover`)."""
        x = np.asarray(points, dtype=np.float64)
        owners = np.unique(_unit_owner(self)) if self.emitters.size else np.zeros(0, np.int64)
        S = len(owners) + len(self.lights) + (self.world is not None)
        out = np.zeros((len(x), S, 3))
        want = np.ones(S, bool) if which is None else np.asarray(which, bool)
        if not len(x) or not want.any():
            return out
        own = eps is not None
        eps = self.offsets(x, normals) if eps is None else \
            np.where(np.isnan(eps), self.offsets(x, normals), np.asarray(eps, dtype=np.float64))
        if want[:len(owners)].any():
            T = self._emitters_at(x, normals, where, samples, eps=eps if own else None)
            L, owner = self.emitted(), _unit_owner(self)
            for j, o in enumerate(owners):
                if want[j]:
                    out[:, j] = T[:, owner == o].astype(np.float64) @ L[owner == o]
        for i, lamp in enumerate(self.lights):
            if want[len(owners) + i]:
                out[:, len(owners) + i] = self._lamp_split(i, x, normals, eps, samples, facing, low)
        if self.world is not None and want[-1]:
            out[:, -1] = self.world_at(x, normals, where, eps=eps if own else None, facing=facing, split=split,
                                       part=part)
        return out

    def _lamp_split(self, i, x, normals, eps, samples, facing, low) -> np.ndarray:
        """(P, 3) lamp ``i``'s radiance at ``x`` for :meth:`split_at`: whole, or with ``low``
        from above the plane of ``facing`` at ``x`` and from below it at ``low``. A sun whose
        disk lies wholly on one side of a point's plane (its direction more than its half angle
        off the plane) is lit from that side only: the other's every sample is left out (0),
        and a leaning texel was lit twice for one answer."""
        def lit(at, nrm, off, side):
            return lamp_irradiance(self.patches, [lamp], self.cache, points=at, normals=nrm, eps=off, index=i,
                                   samples=min(samples or self.light_samples, self.light_samples),
                                   seed=self.light_seed, facing=side, cancelled=self.cancelled,
                                   workers=self.workers) / np.pi
        lamp = self.lights[i]
        if low is None or facing is None:
            return lit(x, normals, eps, None)
        facing, normals = np.asarray(facing, dtype=np.float64), np.asarray(normals, dtype=np.float64)
        up, down = np.ones(len(x), bool), np.all(np.isfinite(low), axis=1)
        if isinstance(lamp, SunLight):
            s, edge = facing @ -np.asarray(lamp.direction, dtype=np.float64), np.sin(0.5 * lamp.angle) + 1e-9
            up &= s > -edge
            down &= s < edge
        out = np.zeros((len(x), 3))
        a = np.flatnonzero(up)
        if a.size:
            out[a] = lit(np.ascontiguousarray(x[a]), normals[a], np.asarray(eps)[a], facing[a])
        r = np.flatnonzero(down)
        if r.size:
            out[r] += lit(np.ascontiguousarray(low[r]), normals[r], np.zeros(r.size), -facing[r])
        return out

    def probed(self) -> np.ndarray:
        """(S,) bool per column of :meth:`split_at`: a source whose light one shadow ray per point
        stands for where it is smooth (an emitting object, a lamp: a bounded source seen or not),
        not the world or an environment map (light from a whole hemisphere)."""
        owners = np.unique(_unit_owner(self)) if self.emitters.size else np.zeros(0)
        lamps = [not isinstance(li, EnvironmentLight) for li in self.lights]
        return np.array([True] * len(owners) + lamps + [False] * (self.world is not None), bool)

    def scene(self):
        """The shadow-ray scene, built once and only if a ray is cast."""
        if self._scene is None:
            self._scene = occluder(self.patches, "auto")
        return self._scene

    def at(self, points, normals, where: str, samples=None, eps=None, facing=None, split=1,
           part=None, sky=None, unbounded=None, emitters=True, lights=True, clamp=True) -> np.ndarray:
        """(P, 3) radiance arriving directly at ``points`` (P, 3) with unit ``normals`` (P, 3).
        ``where`` names the point set in the transport's cache key ('centres', 'vertices', ...).
        ``samples``: fewer shadow rays per point than the bake's, and no more in penumbrae
        (where many points are averaged, as a gather's hits are). ``eps`` (P,): how far the
        rays start off ``points`` along ``normals`` (default :meth:`offsets`; 0 where the points
        are the rays' starts already, :mod:`..output.crease`). ``facing`` (P, 3) or None: the
        lamps' and the world's light only from directions on its side (a corner's own
        triangle's normal, :mod:`..output.crease`); the emitters' is not limited by it.
        ``split``: the points come in runs of that many whose mean is what is read (an abrupt
        cell's, :mod:`..output.abrupt`): each casts ``sky_rays / split`` of the sky's rays, the
        run all of them once; ``part`` (P,): which share each point casts instead
        (:func:`.hemisphere.sky_fraction`). ``sky``: None, or a function that returns the world's
        share (P,) of each point's hemisphere, found by other rays (the final gather's,
        :func:`..output.indirect.gathered_sky`): no sky rays are cast, and it is asked for
        last (the gather casts while the rest is found). ``unbounded`` (P, 3) or None: the
        suns' and environment maps' part (radiance, before the clamp at 0) is added to it too.
        ``emitters`` False: the lamps' and the world's light only; ``lights`` False: the
        emitters' only. ``clamp`` False: the sum as it is (parts found apart are added, then
        clamped once, as here)."""
        D = np.zeros((len(points), 3))
        if self.emitters.size and emitters:
            # the transport's sums as emitters.apply_transport's, bit for bit, several times faster
            D += transport_product(self._emitters_at(points, normals, where, samples, transposed=True, eps=eps),
                                   self.emitted(), transposed=True)
        if self.world is not None and sky is None and lights:
            D += self.world_at(points, normals, where, eps=eps, facing=facing, split=split, part=part)
        if self.lights and lights:
            far = None if unbounded is None else np.zeros((len(points), 3))
            D += lamp_irradiance(self.patches, self.lights, self.cache, points=points, normals=normals,
                                 eps=self.offsets(points, normals) if eps is None else eps,
                                 cancelled=self.cancelled, facing=facing,
                                 samples=min(samples or self.light_samples, self.light_samples),
                                 seed=self.light_seed, workers=self.workers, unbounded=far) / np.pi
            if far is not None:
                unbounded += far / np.pi
        if self.world is not None and sky is not None and lights:
            D += np.asarray(sky(), dtype=np.float64)[:, None] * self.world[None, :]
        # an environment map's variation about its mean is signed (its estimate, near a point
        # that sees little of the sky, can dip below what the mean gives): light is not
        return np.maximum(D, 0.0, out=D) if clamp else D

    def over(self, patches) -> "DirectLight":
        """This bake's lamps and world with their shadow rays through ``patches`` instead (e.g.
        the fronts alone, :mod:`..output.covered`), and no emitting face."""
        return replace(self, patches=patches, emitters=np.zeros(0, np.int64), groups=None, _scene=None)

    def lamps_at(self, points, normals, where: str, eps=None, facing=None) -> np.ndarray:
        """(P, 3) :meth:`at`'s radiance from the lamps alone: no emitting face, no world."""
        return self.at(points, normals, where, eps=eps, facing=facing, sky=lambda: np.zeros(len(points)),
                       emitters=False)


def turns_emitters(settings) -> bool:
    """Whether emitters also shine from their faces turned around (Cycles' two-sided Emission):
    not when open surfaces have backs of their own (``two_sided_reflection``, :mod:`..mesh.backs`),
    whose backs of emitting faces emit; a closed emitter's turned-around faces face its inside."""
    return bool(settings.two_sided_emission and not settings.two_sided_reflection)


def _unit_owner(light: "DirectLight") -> np.ndarray:
    """(units,) the object of each column of the emitters' transport."""
    own = light.patches.owner[light.emitters]
    if light.groups is None:
        return own
    first = np.zeros(int(light.groups.max()) + 1, dtype=own.dtype)
    first[light.groups[::-1]] = own[::-1]
    return first


def _face_groups(patches: PatchSet, emitters, first, of_face) -> np.ndarray | None:
    """(M,) the emitting patches ``emitters`` of each input face as one unit (``of_face`` (M,):
    their face, numbered 0..; ``first``: each face's first row of ``emitters``), or None where
    some face's patches cannot shine as one: not in one plane (a bent quad), or not of one
    emission (a texture's): then every patch shines on its own, sharing its face's rays
    (:meth:`DirectLight.plan`).
    A face's patches cut from one flat face of one emission light as the face does: its form
    factor is its outline's (one contour, :func:`.polygon_ff.group_form_factors`) and its
    ``direct_samples`` rays spread over it by area, as a lamp modelled as many faces and grouped
    into a cluster. Each patch shining apart cost every point a contour and at least 4 rays per
    patch: the Cornell box at 0.05 m patches cut its 0.5 m lamp into 100 of them, 400 rays and
    100 contours per point, most of its bake."""
    groups = np.asarray(of_face, dtype=np.int64).reshape(-1)
    lead = emitters[first][groups]                       # each patch's face's first patch
    same_light = np.all(patches.emission[emitters] == patches.emission[lead], axis=1)
    n, n0 = patches.normals[emitters], patches.normals[lead]
    span = float(np.linalg.norm(patches.verts.max(0) - patches.verts.min(0))) or 1.0
    flat = (np.einsum("ij,ij->i", n, n0) > 1 - 1e-9) & \
        (np.abs(np.einsum("ij,ij->i", patches.centers[emitters] - patches.centers[lead], n0)) <= 1e-7 * span)
    if not np.all(same_light & flat):
        return None
    return groups


def _whole_groups(patches: PatchSet, emitters, groups, min_area) -> np.ndarray:
    """(M,) emitter groups with each group smaller than ``min_area`` joined to the nearest
    group of the same object, in the same plane, that is not (by their area centroids, within
    two patch sizes), renumbered 0.. in order.
    The clusters' grid cuts a lamp wherever its cells fall: the same 0.47 m lamp modelled as
    128 triangles made 4 groups, as 882 made 9 (slivers along two cell borders), and every
    group costs every point ``direct_samples`` shadow rays. A group's form factor is its
    outline's whatever its shape, and its rays spread over it by area, so a joined group
    lights as its parts do; in one plane only, as its rays' visible fraction is shared (a
    point in the plane of one part and facing the other would see half its rays blocked)."""
    a = patches.areas[emitters]
    G = int(groups.max()) + 1
    area = np.bincount(groups, weights=a, minlength=G)
    small = area < min_area
    if not small.any() or small.all():
        return groups
    mid = np.stack([np.bincount(groups, weights=a * patches.centers[emitters, k], minlength=G)
                    for k in range(3)], 1) / area[:, None]
    owner = np.zeros(G, np.int64)
    owner[groups] = patches.owner[emitters]
    nrm = np.stack([np.bincount(groups, weights=a * patches.normals[emitters, k], minlength=G)
                    for k in range(3)], 1)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    flat = np.bincount(groups, weights=a * np.abs(np.einsum("ij,ij->i", patches.normals[emitters],
                                                            nrm[groups])), minlength=G) / area
    reach = 2.0 * np.sqrt(2.0 * min_area)                 # two patch sizes
    to = np.arange(G)
    big = np.flatnonzero(~small & (flat > 1 - 1e-9))
    for g in np.flatnonzero(small & (flat > 1 - 1e-9)):
        d = mid[big] - mid[g]
        same = (owner[big] == owner[g]) & (np.einsum("ij,j->i", nrm[big], nrm[g]) > 1 - 1e-9) & \
            (np.abs(d @ nrm[g]) <= 1e-6 * reach) & (np.linalg.norm(d, axis=1) <= reach)
        if same.any():
            to[g] = big[same][np.argmin(np.linalg.norm(d[same], axis=1))]
    return unique_ints(to[groups], return_inverse=True)[1].reshape(-1)


