"""The whole bake in plain arrays: meshes -> patches -> form factors -> radiosities -> vertices.

This is what the Blender operator and the CLI call; it never touches Blender.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .cache import FormFactorCache, cache_key
from .patches import PatchError, PatchSet, build_patches
from .progress import Cancelled
from .solve import SOLVERS, Solution, solve
from .sparse import CSR
from .direct import apply_transport, vertex_frames
from .interpolate import interpolate_at
from .vertex import exposure, vertex_radiosity

__all__ = ["BakeSettings", "BakeResult", "bake", "compute_form_factors", "source_term", "METHODS"]

METHODS = ("hemicube", "embree", "embree_stochastic")
DIRECT_MODES = ("exact", "hemicube")
AUTO_PATCHES_PER_DIAGONAL = 14.0


@dataclass
class BakeSettings:
    """patch_size: target patch edge length in world units (None/0: one patch per face), or
    'auto': the scene's bounding-box diagonal / 14 (0.25 m for the 2 m Cornell box, the size the
    benchmark's frontier picked; about 1/8 of a room's width whatever its scale).
    resolution: hemi-cube top-face pixels per side (hemicube and embree methods).
    method: 'hemicube' (NumPy rasteriser), 'embree' (rays through the same hemi-cube pixels),
    'embree_stochastic' (cosine-weighted random rays, ``rays_per_patch`` each).
    solver: one of core.solve.SOLVERS; tolerance/max_iterations as in :func:`core.solve.solve`.
    rotate_seed: random rotation of each hemi-cube about its normal (None: no rotation).
    direct: how light from emitters (emissive patches, lamps) reaches the surfaces. 'exact':
    closed-form unshadowed irradiance (Lambert's point-to-polygon formula) times the visible
    fraction from ``direct_samples`` shadow rays per point and emitting face (Embree, or a NumPy
    BVH without it), at patch centres for the solve and again at every vertex for the output
    (sharp shadows and exact falloff without finer patches); F then carries only reflected
    light. 'hemicube': the paper's way, emitted light through F too (lamps at patch centres).
    element_size: the output mesh's detail (world units), finer than ``patch_size``: the paper's
    "finer elements take detail from a coarse patch solution". The solve runs on the patches;
    the output mesh is cut to ``element_size``, direct light is evaluated exactly at each of its
    vertices and light reflected more than once is interpolated bilinearly from the patches.
    None: the patches are the output mesh; 'auto': a third of the patch size (the frontier's
    ratio). Needs ``direct='exact'``.
    max_patches, max_elements: a bake that would cut more stops with an error that says so
    (form factors grow with the square of the patch count).

    Defaults are the speed-against-error frontier of ``make bench`` (docs/performance.md):
    resolution 32 gives the error of 64..256 at half the cost, and 0.25 m patches with 0.08 m
    elements and 64 gather rays reach Cycles' 64-spp vertex error several times faster.
    gather_rays: with elements, the light reflected more than once is *gathered* at each element
    vertex by this many cosine rays that read the patch solution where they land (a final
    gather; needs Embree) instead of interpolated (0).
    """

    patch_size: float | str | None = "auto"
    resolution: int = 32
    method: str = "hemicube"
    rays_per_patch: int = 512
    solver: str = "gauss_seidel"
    tolerance: float = 1e-4
    max_iterations: int = 200
    rotate_seed: int | None = None
    direct: str = "exact"
    direct_samples: int = 16
    element_size: float | str | None = "auto"
    gather_rays: int = 64
    max_patches: int = 20000
    max_elements: int = 400000

    def validate(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"unknown method {self.method!r}; choose one of {', '.join(METHODS)}")
        if self.solver not in SOLVERS:
            raise ValueError(f"unknown solver {self.solver!r}; choose one of {', '.join(SOLVERS)}")
        if self.method != "embree_stochastic" and (self.resolution < 2 or self.resolution % 2):
            raise ValueError(f"hemi-cube resolution must be an even number >= 2, got {self.resolution}")
        if self.method == "embree_stochastic" and self.rays_per_patch < 1:
            raise ValueError(f"rays per patch must be >= 1, got {self.rays_per_patch}")
        for name in ("patch_size", "element_size"):
            v = getattr(self, name)
            if isinstance(v, str) and v != "auto" or not isinstance(v, str) and v is not None and v < 0:
                raise ValueError(f"{name.replace('_', ' ')} must be >= 0 or 'auto', got {v!r}")
        if self.direct not in DIRECT_MODES:
            raise ValueError(f"unknown direct-light mode {self.direct!r}; choose one of {', '.join(DIRECT_MODES)}")
        if self.uses_elements() and self.direct != "exact":
            raise ValueError("finer output elements need direct='exact' (direct light at every element vertex)")
        if not self.tolerance > 0 or self.max_iterations < 1:
            raise ValueError("tolerance must be > 0 and max_iterations >= 1")

    def resolved(self, meshes) -> "BakeSettings":
        """A copy with 'auto' sizes turned into world units for ``meshes``."""
        from dataclasses import replace

        patch, element = self.patch_size, self.element_size
        if patch == "auto":
            lo = np.min([np.min(m.verts, axis=0) for m in meshes], axis=0)
            hi = np.max([np.max(m.verts, axis=0) for m in meshes], axis=0)
            patch = float(np.linalg.norm(hi - lo)) / AUTO_PATCHES_PER_DIAGONAL or None
        if element == "auto":
            element = patch / 3 if patch else None
        return replace(self, patch_size=patch, element_size=element)

    def uses_elements(self) -> bool:
        """True when the output mesh is cut finer than the patches."""
        if not self.element_size:
            return False
        if self.element_size == "auto":
            return bool(self.patch_size)
        if self.patch_size == "auto":
            return True
        return not self.patch_size or self.element_size < self.patch_size

    def form_factor_key(self) -> tuple:
        """What shapes F (besides geometry): a change here recomputes, anything else re-solves."""
        if self.method == "embree_stochastic":
            return (self.method, int(self.rays_per_patch), self.rotate_seed)
        return (self.method, int(self.resolution), self.rotate_seed)


@dataclass
class BakeResult:
    """``patches`` are what was solved (``solution.B`` per patch); ``elements`` is the output mesh
    (the patches themselves unless ``element_size`` cut it finer) and ``vertex_radiosity`` (V, 3)
    is per ``elements.verts``."""

    patches: PatchSet
    form_factors: CSR
    solution: Solution
    vertex_radiosity: np.ndarray
    timings: dict
    form_factor_source: str
    source: np.ndarray
    direct_irradiance: np.ndarray | None = None
    notes: list = field(default_factory=list)
    elements: PatchSet | None = None
    settings: BakeSettings | None = None      # as used: 'auto' sizes resolved to world units

    def __post_init__(self):
        if self.elements is None:
            self.elements = self.patches


def receivers_needed(patches: PatchSet) -> np.ndarray:
    """Patches whose rows of F matter: a patch that reflects nothing (rho = 0 in every band,
    e.g. a pure emitter) has B = S whatever it sees, so its hemi-cube is never drawn."""
    return np.flatnonzero(patches.rho.max(axis=1) > 0)


def compute_form_factors(patches: PatchSet, settings: BakeSettings, *, receivers=None,
                         progress=None, cancelled=None) -> CSR:
    """F for ``patches`` by ``settings.method`` (rows only for ``receivers``, default all)."""
    if settings.method == "hemicube":
        from .hemicube import hemicube_form_factors

        return hemicube_form_factors(patches, settings.resolution, rotate_seed=settings.rotate_seed,
                                     receivers=receivers, progress=progress, cancelled=cancelled)
    from . import embree_ff

    if settings.method == "embree":
        return embree_ff.embree_hemicube_form_factors(
            patches, settings.resolution, rotate_seed=settings.rotate_seed, receivers=receivers,
            progress=progress, cancelled=cancelled)
    return embree_ff.embree_stochastic_form_factors(
        patches, settings.rays_per_patch, seed=settings.rotate_seed or 0, receivers=receivers,
        progress=progress, cancelled=cancelled)


def _exact_direct_plan(patches: PatchSet, settings: BakeSettings, lights):
    """What the exact direct path needs, or None when it is off or there is no direct light."""
    emitters = np.flatnonzero(patches.emission.max(axis=1) > 0)
    if settings.direct == "hemicube" or (emitters.size == 0 and not lights):
        return None
    from functools import lru_cache

    from .lights import occluder

    occ = lru_cache(maxsize=1)(lambda: occluder(patches, "auto"))  # built only if rays are cast
    # shadow rays per emitting *face*: split between the patches it was cut into
    samples = settings.direct_samples
    if emitters.size:
        face = patches.owner[emitters].astype(np.int64) * (1 << 32) + patches.source_face[emitters]
        per_face = np.unique(face, return_counts=True)[1].max()
        samples = max(1, int(settings.direct_samples) // int(per_face))
    return {"emitters": emitters, "scene": occ, "samples": samples}


def _direct_at(patches, points, normals, plan, lights, light_options, cancelled, cache, where):
    """Radiance arriving directly (emitters and lamps) at points: (P, 3).

    The emitters' part goes through a transport matrix that depends on geometry only, cached
    with the form factors: a new emission strength or colour is a matrix product, no rays.
    """
    from .direct import emitter_transport
    from .progress import Ticker

    D = np.zeros((len(points), 3))
    em = plan["emitters"]
    if em.size:
        key = None
        if cache is not None:
            pts = np.ascontiguousarray(points, dtype=np.float64)
            key = cache_key(patches.geometry_key() + em.tobytes() + pts.tobytes(),
                            ("direct", where, plan["samples"]))
        T = cache.get(key) if key else None
        if T is None:
            T = emitter_transport(patches, points, normals, em, scene=plan["scene"](),
                                  samples=plan["samples"], ticker=Ticker(None, cancelled))
            if key:
                cache.put(key, T)
        D += apply_transport(T, patches.emission[em])
    if lights:
        from .lights import direct_irradiance

        D += direct_irradiance(patches, lights, points=points, normals=normals, cancelled=cancelled,
                               **(light_options or {})) / np.pi
    return D


def meshes_key(meshes) -> bytes:
    """Bytes that change exactly when the source meshes' geometry changes (not materials)."""
    import hashlib

    h = hashlib.sha256()
    for m in meshes:
        for a in (m.verts, m.face_offsets, m.face_indices):
            a = np.ascontiguousarray(a)
            h.update(str(a.shape).encode() + a.tobytes())
    return h.digest()


def _cached(cache, key, make):
    item = cache.get(key) if cache is not None else None
    if item is None:
        item = make()
        if cache is not None:
            cache.put(key, item)
    return item


def output_elements(meshes, settings, cache=None) -> PatchSet:
    """The output mesh cut to ``settings.element_size``; its geometry is cached (a relight only
    re-reads reflectivity and emission from the meshes)."""
    key = cache_key(meshes_key(meshes), ("elements", settings.element_size))
    el = _cached(cache, key, lambda: build_patches(meshes, settings.element_size))
    rho = np.empty((len(el), 3))
    em = np.empty((len(el), 3))
    for oi, m in enumerate(meshes):
        sel = el.owner == oi
        rho[sel] = np.asarray(m.face_rho, float)[el.source_face[sel]]
        em[sel] = np.asarray(m.face_emission, float)[el.source_face[sel]]
    return el.with_materials(rho, em)


def _element_indirect(patches, elements, rest_v, xv, nv, rho_v, plan, lights, light_options, cancelled, cache,
                      settings, world, notes):
    """Light reflected more than once arriving at element vertices, times their reflectivity:
    a final gather over the patch solution (its ray hits cached as a matrix), or the solution's
    bilinear interpolation."""
    from .embree_ff import embree_available

    if settings.gather_rays > 0 and embree_available():
        from .embree_ff import embree_scene
        from .gather import apply_gather, gather_matrix
        from .progress import Ticker

        # the patches' reflected radiance R = rho (D + gathered) at their vertices, with the
        # direct part exact at each vertex so that shadows are not smeared into what is gathered
        pxv, pnv, prho = vertex_frames(patches)
        R_v = prho * _direct_at(patches, pxv, pnv, plan, lights, light_options, cancelled, cache,
                                "patch-vertices") + rest_v

        def make():
            G, sky = gather_matrix(patches, xv, nv, embree_scene(patches), rays=settings.gather_rays,
                                   ticker=Ticker(None, cancelled))
            G.sky = sky
            return G

        key = cache_key(patches.geometry_key() + elements.geometry_key(), ("gather", settings.gather_rays))
        G = _cached(cache, key, make)
        return rho_v * apply_gather(G, G.sky, R_v, world)
    if settings.gather_rays > 0:
        notes.append("Embree is not available: element vertices interpolate the patch solution "
                     "instead of gathering it")
    owner_v = np.zeros(len(elements.verts), np.int64)
    for c in range(4):
        on = elements.polys[:, c] >= 0
        owner_v[elements.polys[on, c]] = elements.owner[on]
    return interpolate_at(patches, rest_v, xv, owner=owner_v, normals=nv)


def source_term(patches: PatchSet, F: CSR, *, direct_irradiance=None, world=None) -> np.ndarray:
    """S = emission + rho * H_direct / pi + rho * sky * L_world  (radiance units, (N, 3)).

    ``direct_irradiance`` (N,3) W/m^2 from lamps; ``world`` (3,) constant world radiance seen by
    the part of each hemisphere that sees no surface (``F.sky``).
    """
    S = np.array(patches.emission, dtype=np.float64)
    if direct_irradiance is not None:
        S += patches.rho * np.asarray(direct_irradiance, float) / np.pi
    if world is not None and np.any(np.asarray(world) > 0):
        if F.sky is None:
            raise ValueError("these form factors carry no sky fractions; the world cannot be lit")
        S += patches.rho * F.sky[:, None] * np.asarray(world, float)[None, :]
    return S


def bake(meshes, settings: BakeSettings | None = None, *, progress=None, cancelled=None,
         lights=(), world=None, cache: FormFactorCache | None = None, patches: PatchSet | None = None,
         light_options=None) -> BakeResult:
    """Run every stage. ``progress(stage, fraction, message)``; ``cancelled() -> bool`` (raises
    :class:`Cancelled`). ``lights``: core.lights light objects; ``world``: (3,) radiance.
    ``cache``: a :class:`FormFactorCache`; a hit skips the form-factor stage.
    ``patches``: a ready PatchSet (then ``meshes`` is not cut again).
    """
    settings = settings or BakeSettings()
    settings.validate()
    if meshes is not None:
        settings = settings.resolved(meshes)
    elif "auto" in (settings.patch_size, settings.element_size):
        raise ValueError("'auto' sizes need the meshes")
    say = progress or (lambda stage, fraction, message="": None)
    t0 = time.perf_counter()
    timings = {}

    def check():
        if cancelled is not None and cancelled():
            raise Cancelled("cancelled")

    say("patches", 0.0, "cutting meshes into patches")
    if patches is None:
        patches = build_patches(meshes, settings.patch_size)
    if len(patches) > settings.max_patches:
        raise PatchError(f"a patch size of {settings.patch_size} cuts the scene into {len(patches)} patches, "
                         f"more than the limit of {settings.max_patches}: use a larger patch size "
                         "(and a detail size for sharp output)")
    timings["patches"] = time.perf_counter() - t0
    say("patches", 1.0, f"{len(patches)} patches")
    check()

    t = time.perf_counter()
    key = cache_key(patches.geometry_key(), settings.form_factor_key()) if cache is not None else None
    F = cache.get(key) if cache is not None else None
    source = "cached" if F is not None else "computed"
    if F is None:
        recv = receivers_needed(patches)
        started = time.perf_counter()

        def ff_progress(fr):
            el = time.perf_counter() - started
            eta = el * (1 - fr) / fr if fr > 0 else float("nan")
            say("form_factors", fr, f"{100 * fr:.0f}%  ETA {eta:.1f} s")

        F = compute_form_factors(patches, settings, receivers=recv, progress=ff_progress,
                                 cancelled=cancelled)
        F.meta.setdefault("receivers", int(recv.size))
        if cache is not None:
            cache.put(key, F)
    timings["form_factors"] = time.perf_counter() - t
    say("form_factors", 1.0, f"{source}: {F.nnz} nonzeros, {F.nbytes / 1e6:.1f} MB")
    check()

    t = time.perf_counter()
    lights = list(lights or ())
    exact = _exact_direct_plan(patches, settings, lights)
    notes = []
    H = None
    if exact is None:
        if lights:
            from .lights import direct_irradiance

            say("direct", 0.0, f"{len(lights)} lights")
            H = direct_irradiance(patches, lights, cancelled=cancelled, **(light_options or {}))
        S = source_term(patches, F, direct_irradiance=H, world=world)
    else:
        # direct light (emitters and lamps) arrives by the exact path; the solve carries only
        # reflected light R, and B = E + R (F would otherwise carry E a second time)
        say("direct", 0.0, f"exact direct light: {exact['emitters'].size} emitting patches, {len(lights)} lamps")
        D_patch = _direct_at(patches, patches.centers, patches.normals, exact, lights, light_options,
                             cancelled, cache, "centres")
        H = np.pi * D_patch
        S = source_term(patches, F, world=world) - patches.emission + patches.rho * D_patch
        from .embree_ff import embree_available

        if not embree_available():
            notes.append("Embree is not available: shadow rays use the slower NumPy BVH")
    timings["direct"] = time.perf_counter() - t
    check()

    t = time.perf_counter()
    computed = np.zeros(len(patches), bool)
    computed[receivers_needed(patches)] = True
    say("solve", 0.0, settings.solver)
    sol = solve(F, patches.rho, S, settings.solver, settings.tolerance, settings.max_iterations,
                areas=patches.areas, cancelled=cancelled, computed=computed,
                progress=lambda fr: say("solve", fr, ""))
    timings["solve"] = time.perf_counter() - t
    say("solve", 1.0, f"{sol.iterations} iterations, residual {sol.residual:.2e}"
        + ("" if sol.converged else " (NOT converged: raise max iterations)"))
    check()

    t = time.perf_counter()
    elements = patches
    w = exposure(F)
    if exact is None:
        Bv = vertex_radiosity(patches, sol.B, weights=w)
    else:
        # direct light again at every output vertex (sharp shadows, exact falloff); only the
        # smoother light reflected more than once comes from the patches, as in the paper
        rest = sol.B - patches.rho * D_patch
        rest_v = vertex_radiosity(patches, rest, weights=w)
        if settings.uses_elements():
            say("vertices", 0.0, f"cutting output elements of {settings.element_size:g}")
            elements = output_elements(meshes, settings, cache)
            if len(elements) > settings.max_elements:
                raise PatchError(f"a detail size of {settings.element_size} cuts the scene into "
                                 f"{len(elements)} output elements, more than the limit of "
                                 f"{settings.max_elements}: use a larger detail size")
            xv, nv, rho_v = vertex_frames(elements)
            rest_v = _element_indirect(patches, elements, rest_v, xv, nv, rho_v, exact, lights, light_options,
                                       cancelled, cache, settings, world, notes)
        else:
            xv, nv, rho_v = vertex_frames(patches)
        D_vert = _direct_at(patches, xv, nv, exact, lights, light_options, cancelled, cache, "vertices")
        Bv = vertex_radiosity(elements, elements.emission) + rho_v * D_vert + rest_v
        sol.extra["reflected_only"] = True
        sol.B = sol.B + patches.emission
    timings["vertices"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    if not sol.converged:
        notes.append(f"solver stopped after {sol.iterations} iterations without reaching "
                     f"tolerance {settings.tolerance:g}")
    return BakeResult(patches, F, sol, Bv, timings, source, S, H, notes, elements, settings)
