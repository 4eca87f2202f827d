"""How long a bake will take, said before its long work starts (the memory is
:func:`..mesh.stage.form_factor_gb`'s, said by the patch stage).

A bake's time goes to two kinds of work (``docs/performance.md``): the form factors, per
receiver (one hemi-cube each), and the output, per output vertex (the final gather's rays, the
exact direct light and what shines; less where no emitting face lights the scene,
:data:`PER_VERTEX_LAMPS`, or no gather runs, :data:`PER_VERTEX_EMITTERS`, more for every lamp
past the first, :data:`PER_EXTRA_LAMP`, and for
what shines where lamps other than suns light it, :data:`PER_VERTEX_SHINE`). The form factors' are measured: the hemi-cube draws a sample of its
receivers first, spread through the scene, and times them (up to 0.3 s or 2% of them:
:func:`..form_factors.hemicube._probe`); where there are too few to sample (or another method
makes them) they are counted, per receiver and per polygon drawn in its hemi-cube
(:func:`polygons_seen`). A hemi-cube's cost varies fourfold with the scene at the same count
of polygons seen (1.6 ms in the living room, 1.9 ms on the terrain, 3.3 ms in the truck town
and the bunny, 6.7 ms in zdm2), which the count alone put 0.6-2x off. The output's rates were
measured on one worker (``bench/bench_dense.py`` prints the forecast beside the time it took;
``docs/performance.md``), from the Cornell box, the box tessellated ever finer and Suzanne
subdivided, and where lamps, suns and the world light the scene fitted to the real scenes'
sun and sky from what each part of the output stage took: per vertex, more the more of its
rays meet a surface, per element a lamp's shadow edge crosses (the abrupt elements'
corrections) and per corner lit on its own (a shading normal leaning off its triangle's),
each counted on a sample before the form factors by a few thousand rays
(:func:`rays_ahead`) and corner normals (:func:`leaning_ahead`). The output is the stage
least sure, from 0.7x (the terrain) to 1.4x (the truck town, whose cut along contacts adds a
third to its vertices) of its forecast, and :meth:`Forecast.describe` says so. Where Embree's
rays make the form factors (:func:`ray_seconds`) they are counted, not timed: within 0.55-1.5x
on the real scenes. The
whole bake came out between about 0.6 and 1.8 times the forecast, hence the range :data:`SPREAD`. It is said once the patches are known and before the form factors, with the
output elements cut already (cached: the vertex stage finds them), and kept on the result
(``BakeResult.forecast``, the report's 'forecast'); a bake whose form factors come from the
cache (a relight) has nothing long to forecast.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..light.environment import RAYS_PER_SKY_RAY, EnvironmentLight
from ..light.lamps import SunLight
from ..output.indirect import DENSE_RAY_DIVISOR, gathers_faces
from ..output.shine import BUDGET
from .parallel import resolve_workers

__all__ = ["Forecast", "forecast", "SAID"]

#: How :meth:`Forecast.describe` begins (a headless run prints such a message at once).
SAID = "expected about"

#: Seconds per receiver's hemi-cube, and per polygon it draws (one worker): in front of the
#: receiver and facing it (:func:`polygons_seen`). The per-polygon rate fitted to the real
#: scenes' idle times (``docs/performance.md``, 2 workers): a hemi-cube took 1.1 ms for the
#: living room's 1,460 polygons seen, 2.4 ms for the truck town's 7,500, 6.5 ms for zdm2's
#: 10,600 (an indoor level: every wall faces the receivers), 2.5 ms for the bunny's 4,100 (a
#: convex body turns most of itself away). This says 1.3, 2.0, 1.0 and 1.15 times those; one
#: rate per curved piece (every piece of a curved cluster, seen or not) said 0.7, 0.8, 0.4
#: (zdm2's form factors 2.4 times their forecast) and 1.6.
PER_RECEIVER = 6e-4
PER_SEEN = 5.5e-7
#: Seconds per receiver and per hemi-cube pixel of Embree's rays through them (method 'embree',
#: one worker), fitted to the Cornell box cut into 2,529 and 12,672 patches at resolutions 8, 32
#: and 64: 0.08-0.12, 1.2-1.4 and 4.7-5.0 ms a receiver, where the rasteriser took 0.6-1.1,
#: 1.4-4.3 and 2.3-6.3 ms (about 1,600 and 8,400 polygons seen; one process, the machine busy).
PER_RAY_RECEIVER = 5e-5
PER_PIXEL_RAY = 3.8e-7
#: Receivers :func:`polygons_seen` looks from (a fixed, even sample: the same forecast each time).
SEEN_SAMPLE = 64
#: Seconds per output vertex at 128 gather rays, the default (the exact direct light, the gather,
#: what shines), where emitting faces light the scene (their transport and what shines are
#: most of it: the Cornell box, ``bench_dense.py``) ...
PER_VERTEX = 2.2e-4
#: ... where emitting faces light the scene and no gather runs (the patches are the output):
#: their transport at the vertices, fitted to bitterli_wooden_staircase (255,924 vertices, 31.5 s
#: of one worker's on an idle machine, less its leaning corners' :data:`PER_LEANING`) ...
PER_VERTEX_EMITTERS = 1.0e-4
#: ... and where only lamps, suns and the world do: per vertex, plus per vertex times the share
#: of the rays from it that meet a surface (:func:`rays_ahead`'s ``hit``: a gather ray that
#: finds the sky costs little, one that hits is read, corrected and summed). Fitted with
#: :data:`PER_EDGE` and :data:`PER_LEANING` to the CPU time each part of the output stage took
#: on the real scenes (``bench/forecast_parts.py``, 2 workers, the machine busy), then scaled
#: by one factor (0.81) to their idle times (``bench/real_scenes.py``). Per casting vertex, less
#: the corrections and corners, the bunny (hit 0.09) took 0.092 ms of CPU, the terrain (0.39)
#: 0.14, the living room (0.62) 0.23, the truck town (0.40) 0.34, zdm2 (0.71) 0.37. The truck
#: town's and zdm2's cut along contacts adds a third to their vertices (40,200 for the 30,296
#: counted, 152,134 for 113,789), the living room's a ninth, the terrain's 5%: nothing counted
#: before the form factors says it.
PER_VERTEX_LAMPS = 4.9e-5
PER_VERTEX_HIT = 2.5e-4
#: Seconds per output element a lamp's shadow edge crosses (:func:`rays_ahead`'s ``edges``),
#: one worker: the abrupt elements' grids, corrections and cells (``indirect._corrections``:
#: 1.4 s of CPU in the living room for 1,100 such elements, 6.9 s in the truck town for 2,400,
#: 20.4 s in zdm2 for 5,300, 0.5 s on the bunny for 850, 0.2 s on the terrain for 150).
PER_EDGE = 1.39e-3
#: Seconds per element corner whose shading normal leans more than the crease angle off its
#: triangle's (:func:`leaning_ahead`), one worker: lit on its own (:mod:`..output.crease`; the
#: living room took 1.1 s of CPU for its 34,000 such corners, the truck town 3.3 s for 32,000,
#: zdm2 1.5 s for 26,000).
PER_LEANING = 4.5e-5
#: Element corners :func:`leaning_ahead` looks at (evenly spread), elements :func:`rays_ahead`
#: looks for a shadow's edge across, and the elements it casts :data:`SKY_RAYS` rays each from.
LEAN_SAMPLE = 8192
EDGE_SAMPLE = 2048
SKY_SAMPLE = 256
SKY_RAYS = 32
#: The share :data:`PER_VERTEX_HIT` takes where no ray says it (no Embree: no gather either).
HIT = 0.5
#: What an output vertex that casts no gather rays of its own costs, as a share of
#: :data:`PER_VERTEX` or :data:`PER_VERTEX_LAMPS`: a flat-shaded mesh's corners at one place
#: cast one set between them (:mod:`..output.shared`, counted ahead by
#: :func:`..output.shared.joined_ahead`). The bunny's 201,570 vertices cast from 35,887 places:
#: its vertex stage took 0.55 of the CPU time it took when each cast its own (11.4 s and 20.5 s,
#: bench/real_scenes.py, 2 workers, a busy machine), which this says.
PER_JOINED = 0.46
#: Seconds per output vertex for each lamp past the first (one worker): its shadow rays at the
#: vertices, the abrupt elements' grids and cells, the elements' insides. The rates above were
#: fitted to one sun; this one to sauer_pandora's six soft point lamps (108,794 output vertices;
#: the bench's only scene of several lamps), by its form factors' and output stage's time on an
#: idle machine (55.9 s at 8b2c235, 2 workers): this puts its forecast at 75 s (range 45-150 s).
#: Counted in CPU time (``bench/forecast_parts.py sauer_pandora``, a loaded machine: 100.8 s
#: for the output stage, 57.7 s of it the abrupt elements' corrections) it would be about 7e-5;
#: the range is checked against wall time, which that CPU time, taken under load, overstates.
PER_EXTRA_LAMP = 3e-5
#: Seconds per output vertex and group that shines (:mod:`..output.shine`: a contour and
#: shadow rays each), one worker, where lamps other than suns light the scene: their pools of
#: light shine, as many groups as :data:`..output.shine.BUDGET` allows (sauer_pandora's six
#: point lamps lit 681; the 64 that shone took 10.0 s on 2 workers for 108,794 vertices), while
#: a sun and a sky light no area that brightly (the living room and truck town shine none).
#: Emitting faces' are in :data:`PER_VERTEX`.
PER_VERTEX_SHINE = 2e-6
#: Seconds per shadow ray toward an environment map's directions (one worker), and the points
#: the output stage lights with it per output vertex (the vertices, their corners lit on their
#: own, the abrupt elements' grids and cells), each casting toward the half of the map's
#: directions above its horizon (``RAYS_PER_SKY_RAY`` x Sky Rays): 1.8e-7 s a ray in the window-lit room of
#: ``tests/blender/test_environment_window.py`` (4 points a vertex), 2.4e-7 s in
#: bitterli_grey_white_room (8 points a vertex: 673 M rays, 163 s of the bake's 300 s of CPU;
#: the machine busy). Two scenes, so a rough rate.
PER_ENV_RAY = 2.1e-7
ENV_POINTS = 6.0
#: The other stages (patches, refinement, direct light at the patches, solve) as a share of these.
OTHER = 0.15
#: The time taken over the forecast, as measured (module docstring), the most for ``make demo``'s
#: bake of the Cornell box in a new process (its start-up counts too). Said as a range
#: beside the figure, with a margin above, so that a bake in the Cornell box's case (the most
#: over its forecast) is not a surprise.
SPREAD = (0.6, 2.0)
#: Speed-up of each worker after the first (``docs/performance.md``, 'Both cores').
PER_EXTRA_WORKER = 0.4


@dataclass
class Forecast:
    """Seconds expected for a bake: ``form_factors`` and ``output`` (the vertex stage) on
    ``workers`` workers, ``seconds`` in all; for ``receivers`` hemi-cubes with ``curved``
    pieces drawn one by one and about ``seen`` polygons drawn in each (:func:`polygons_seen`),
    and ``vertices`` output vertices; ``per_receiver``: the seconds a hemi-cube took in the
    sample drawn first (None: none drawn, the form factors counted); ``hit``, ``edges`` and
    ``leaning``: the output's counts (:func:`rays_ahead`, :func:`leaning_ahead`), ``joined`` its
    vertices that cast no gather rays of their own (:data:`PER_JOINED`)."""

    seconds: float
    form_factors: float
    output: float
    receivers: int
    curved: int
    vertices: int
    workers: int
    seen: float = 0.0
    per_receiver: float | None = None
    hit: float | None = None
    edges: float = 0.0
    leaning: float = 0.0
    joined: int = 0

    def describe(self) -> str:
        lo, hi = (_seconds(self.seconds * k) for k in SPREAD)
        return (f"{SAID} {_seconds(self.seconds)} s ({lo}-{hi} s) on {self.workers} worker"
                f"{'s' if self.workers > 1 else ''} (form factors {self.form_factors:.1f} s for "
                f"{self.receivers} hemi-cubes{', timed on a sample' if self.per_receiver else ''}, output {self.output:.1f} s for {self.vertices} vertices, "
                f"the least sure)")

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def hemicube_seconds(seen: float) -> float:
    """Seconds a hemi-cube takes on one worker drawing about ``seen`` polygons."""
    return PER_RECEIVER + PER_SEEN * float(seen)


def ray_seconds(resolution: int) -> float:
    """Seconds Embree's rays through a hemi-cube of ``resolution`` take on one worker."""
    return PER_RAY_RECEIVER + PER_PIXEL_RAY * 3 * int(resolution) ** 2


def polygons_seen(patches, clusters, centers, normals, sample=SEEN_SAMPLE) -> float:
    """About how many polygons a hemi-cube draws: the mean over ``sample`` receivers, evenly
    spread through ``centers`` (R, 3) with unit ``normals`` (R, 3), of the pieces in front of the
    receiver and facing it, a piece of a flat cluster counted as 2 / its cluster's pieces (a
    flat cluster is drawn as its outline, :mod:`..form_factors.drawn`), any other as 1. Costs
    ``sample`` x pieces comparisons (zdm2's 63,000 pieces: a few milliseconds)."""
    c = np.asarray(patches.centers, dtype=np.float64)
    m = np.asarray(patches.normals, dtype=np.float64)
    if not len(c) or not len(centers):
        return 0.0
    w = np.ones(len(c))
    if clusters is not None:
        of = np.asarray(clusters.of, dtype=np.int64)
        bent = _bent(patches, of)
        size = np.bincount(of, minlength=len(bent))
        w = np.where(bent[of], 1.0, 2.0 / np.maximum(size[of], 1))
    pick = np.unique(np.linspace(0, len(centers) - 1, min(sample, len(centers))).astype(np.int64))
    x, n = np.asarray(centers, np.float64)[pick], np.asarray(normals, np.float64)[pick]
    cm = np.einsum("ij,ij->i", c, m)
    total = 0.0
    for s in range(0, len(x), 16):                       # (pieces, 16) at a time
        xs, ns = x[s:s + 16], n[s:s + 16]
        front = c @ ns.T > np.einsum("ij,ij->i", xs, ns)[None]
        facing = cm[:, None] < m @ xs.T
        total += float((w @ (front & facing)).sum())
    return total / len(x)


def _bent(patches, of) -> np.ndarray:
    """(K,) bool: clusters ``of`` (N,) whose pieces do not all share one normal."""
    first = np.full(int(of.max(initial=-1)) + 1, -1, np.int64)
    first[of[::-1]] = np.arange(len(of))[::-1]
    bent = np.abs(patches.normals - patches.normals[first[of]]).max(axis=1) > 1e-6
    curved = np.zeros(len(first), bool)
    curved[of[bent]] = True
    return curved


def curved_pieces(patches, clusters) -> int:
    """Pieces in clusters whose pieces do not all share one normal: a hemi-cube draws them face
    by face (a flat cluster is drawn as its outline). None without clusters: each piece is a
    patch then, counted as a receiver."""
    if clusters is None:
        return 0
    of = np.asarray(clusters.of, dtype=np.int64)
    return int(_bent(patches, of)[of].sum())


def forecast(ctx, receivers, output_vertices: int, per_receiver=None, mesh=None,
             joined: int = 0) -> Forecast:
    """The :class:`Forecast` of the bake of ``ctx`` (after its patch stage) with ``receivers``
    hemi-cubes to draw (their ids among ``ctx.unknowns``, or how many: then looked at from all
    of them) and ``output_vertices`` to evaluate. ``per_receiver``: the seconds a hemi-cube
    took on one worker in a sample of this scene's (:func:`..form_factors.hemicube._probe`),
    which the form factors' forecast then is; None: the rates :data:`PER_RECEIVER` and
    :data:`PER_SEEN`. ``mesh``: the output mesh as counted before the form factors
    (:func:`..mesh.elements.output_mesh_ahead`), whose leaning corners (:func:`leaning_ahead`),
    shadow edges and rays that meet a surface (:func:`rays_ahead`) are counted; None: none.
    ``joined``: output vertices that cast no gather rays of their own
    (:func:`..output.shared.joined_ahead`, :data:`PER_JOINED`)."""
    s = ctx.settings
    workers = resolve_workers(s.workers)
    speed = 1.0 + PER_EXTRA_WORKER * (workers - 1)
    u = ctx.unknowns if hasattr(ctx, "unknowns") else ctx.patches
    ids = np.arange(int(receivers)) if np.ndim(receivers) == 0 else np.asarray(receivers, np.int64)
    ids = ids[ids < len(u.centers)]
    seen = polygons_seen(ctx.patches, ctx.clusters, u.centers[ids], u.normals[ids])
    if per_receiver is None:
        per_receiver_said = ray_seconds(s.resolution) if s.method == "embree" else hemicube_seconds(seen)
    else:
        per_receiver_said = per_receiver
    ff = len(ids) * per_receiver_said / speed
    rays = max(int(getattr(s, "gather_rays", 0) or 0), 32)
    if gathers_faces(ctx):                # a dense scene's faces gather with a share of them
        rays = max(rays // DENSE_RAY_DIVISOR, 1)
    emitting = ctx.patches.emitting().any()
    lamps = list(getattr(ctx, "lights", ()))
    gathers = s.gather_rays > 0 and (s.uses_elements() or gathers_faces(ctx))
    casting = output_vertices - (1 - PER_JOINED) * min(max(int(joined), 0), output_vertices) * gathers
    hit, edges, leaning = None, 0.0, 0.0
    if mesh is not None:
        leaning = leaning_ahead(mesh, ctx.meshes)
        if not emitting:
            hit, edges = rays_ahead(ctx.patches, mesh, lamps, sky=gathers)
    if emitting:
        rate = PER_VERTEX * rays / 128 if gathers else PER_VERTEX_EMITTERS
    else:
        rate = (PER_VERTEX_LAMPS + PER_VERTEX_HIT * (HIT if hit is None else hit)) * rays / 128
    maps = [lamp for lamp in lamps if isinstance(lamp, EnvironmentLight)]   # counted apart, below
    out = casting * rate + output_vertices * PER_EXTRA_LAMP * max(len(lamps) - len(maps) - 1, 0) \
        + PER_EDGE * edges + PER_LEANING * leaning
    # what shines, at most BUDGET groups (not where a dense scene's faces gather: they shine
    # nothing, ``indirect._corrections``)
    shines = any(not isinstance(lamp, SunLight) for lamp in lamps) and not gathers_faces(ctx)
    if not emitting and gathers and shines:
        out += output_vertices * BUDGET * PER_VERTEX_SHINE
    env_rays = RAYS_PER_SKY_RAY * int(s.sky_rays) * sum(bool(m.cast_shadows) for m in maps)
    out += output_vertices * ENV_POINTS * 0.5 * env_rays * PER_ENV_RAY    # toward a map's directions
    out /= speed
    return Forecast((1 + OTHER) * (ff + out), ff, out, len(ids), curved_pieces(ctx.patches, ctx.clusters),
                    int(output_vertices), workers, float(seen), per_receiver,
                    None if hit is None else float(hit), float(edges), float(leaning),
                    int(max(int(joined), 0) * gathers))


def leaning_ahead(mesh, meshes, sample=LEAN_SAMPLE) -> float:
    """About how many corners of ``mesh`` have a shading normal (``meshes``' corner normals,
    :func:`..output.normals.corner_shading_normals`) leaning more than the crease angle off their
    triangle's normal (:func:`..output.crease.leans`): the corners lit on their own
    (:data:`PER_LEANING`), counted on ``sample`` corners evenly spread and scaled to all."""
    from ..output.crease import leans
    from ..output.lift import corner_normals
    from ..output.normals import corner_shading_normals

    p, c = np.nonzero(mesh.polys >= 0)
    if not len(p):
        return 0.0
    pick = np.unique(np.linspace(0, len(p) - 1, min(sample, len(p))).astype(np.int64))
    shade, has = corner_shading_normals(mesh, meshes, p[pick], c[pick])
    if shade is None or not has.any():
        return 0.0
    geo = corner_normals(mesh, p[pick][has], c[pick][has])
    return float(leans(shade[has], geo).sum()) * len(p) / len(pick)


def rays_ahead(patches, mesh, lights, sky=True, sample=SKY_SAMPLE, rays=SKY_RAYS, elements=EDGE_SAMPLE):
    """(hit, edges) a few thousand rays say before the form factors: ``hit`` the share of cosine
    rays (``rays`` each from the centres of ``sample`` elements of the output ``mesh``, evenly
    spread) that meet a surface of ``patches`` (what the gather's rays read, one minus the sky
    they see: :data:`PER_VERTEX_HIT`), and ``edges`` how many elements of ``mesh`` a shadow's
    edge crosses: of ``elements`` of them evenly spread, those whose corners do not all see
    one of ``lights`` (:data:`PER_EDGE`), scaled to the mesh. ``hit`` is None without ``sky``
    or Embree (``edges`` 0 then). Geometry only, in the form factors' own Embree scene (made
    once per geometry): nothing of the bake changes."""
    from ..hemisphere import cosine_lattice
    from ..rays import embree_available, embree_scene

    # lamps with a place or a direction (an environment map's light has neither: no edge counted)
    lit = [li for li in lights if getattr(li, "cast_shadows", True)
           and (isinstance(li, SunLight) or hasattr(li, "position") or hasattr(li, "matrix_world"))]
    if not embree_available() or not len(patches) or not (sky or lit):
        return None, 0.0
    scene = embree_scene(patches)                      # the form factors' own (built once)
    eps = 1e-5 * float(scene.scale)
    hit = None
    if sky and len(mesh.polys):
        pick = np.unique(np.linspace(0, len(mesh.polys) - 1, min(sample, len(mesh.polys))).astype(np.int64))
        x, n = np.asarray(mesh.centers, np.float64)[pick], np.asarray(mesh.normals, np.float64)[pick]
        t = np.cross(n, np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        b = np.cross(n, t)
        loc = cosine_lattice(int(rays))
        d = (loc[None, :, :1] * t[:, None] + loc[None, :, 1:2] * b[:, None] + loc[None, :, 2:] * n[:, None])
        o = np.repeat(x + eps * n, len(loc), axis=0)
        hit = float(np.mean(scene.occluded(o, d.reshape(-1, 3))))
    edges = 0.0
    if lit and len(mesh.polys):
        pick = np.unique(np.linspace(0, len(mesh.polys) - 1, min(elements, len(mesh.polys))).astype(np.int64))
        polys = mesh.polys[pick]
        p, c = np.nonzero(polys >= 0)
        v = polys[p, c]
        x = mesh.verts[v] + 1e-2 * (mesh.centers[pick][p] - mesh.verts[v]) + eps * mesh.normals[pick][p]
        cross = np.zeros(len(pick), bool)
        for li in lit:
            if isinstance(li, SunLight):
                d, far = np.broadcast_to(-np.asarray(li.direction, np.float64), x.shape), None
            else:                               # a point, spot or area light's centre
                at = li.position if hasattr(li, "position") else np.asarray(li.matrix_world)[:3, 3]
                d, far = np.asarray(at, np.float64) - x, np.full(len(x), 1.0 - 1e-4)
            seen = (np.einsum("ij,ij->i", d, mesh.normals[pick][p]) > 0) & ~scene.occluded(x, d, far)
            some = np.bincount(p, seen, minlength=len(pick))
            cross |= (some > 0) & (some < np.bincount(p, minlength=len(pick)))
        edges = float(cross.mean()) * len(mesh.polys)
    return hit, edges


def _seconds(x: float) -> str:
    return f"{x:.1f}" if x < 10 else f"{x:.0f}"
