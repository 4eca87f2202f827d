"""The whole bake in plain arrays: meshes -> patches -> form factors -> radiosities -> vertices.

:func:`bake` runs :data:`STAGES` in order over one :class:`BakeContext`; each stage is a function
in the module that owns its work, reads what earlier stages left on the context and adds its own.
Every stage is timed and reported the same way (``progress(stage, fraction, message)`` and
``result.timings[stage]``). This is what the Blender operator and the CLI call; it never touches
Blender.
"""
from __future__ import annotations

import importlib
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import numpy as np

from .runtime.cache import FormFactorCache, cache_key, cached
from .mesh.clusters import Clusters, group_pieces
from .light.points import patch_average
from .light.stage import DirectLight, direct_stage, source_term
from .runtime.errors import SettingsError
from .output.estimate import estimate_stage
from .light.lamps import SpotLight, SunLight, direct_irradiance
from .form_factors.stage import compute_form_factors, form_factor_stage, receivers_needed
from .mesh.contact import cut_along_contacts
from .mesh.elements import mesh_faces, meshes_key, output_elements, start_elements
from .output.stage import vertex_stage
from .runtime.native import kept_heap, one_blas_thread
from .mesh.patches import PatchError, PatchSet
from .mesh.subdivide import build_patches, keeps_faces_whole
from .runtime.progress import Cancelled
from .mesh.refine import refine_stage
from .settings import BakeSettings
from .solve.solvers import Solution, solve
from .util.sparse import CSR

__all__ = ["BakeSettings", "BakeContext", "BakeResult", "bake", "STAGES", "compute_form_factors",
           "receivers_needed", "source_term", "output_elements"]


@dataclass
class BakeResult:
    """``patches`` are the pieces of surface that were drawn and lit; ``solution.B`` is per
    patch, or per cluster where small faces were grouped (``clusters``); ``elements``
    is the output mesh (the patches themselves unless ``element_size`` cut it finer) and
    ``vertex_radiosity`` (V, 3) is per ``elements.verts``. ``source`` (N, 3) is the solve's source
    term and ``direct_irradiance`` (N, 3) W/m^2 the direct light at the patch centres (or None)."""

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
    clusters: Clusters | None = None          # small faces grouped: solution.B is per cluster
    error_estimate: object = None             # core.output.estimate.ErrorEstimate with settings.estimate_error
    forecast: object = None                   # core.runtime.forecast.Forecast: the time expected (None: F was cached)

    def __post_init__(self):
        if self.elements is None:
            self.elements = self.patches

    @property
    def unknowns(self) -> int:
        """How many patches were solved for (clusters, or the patches themselves)."""
        return len(self.patches if self.clusters is None else self.clusters)

    @property
    def patch_radiosity(self) -> np.ndarray:
        """(N, 3) radiosity of every patch (its cluster's, where faces were grouped)."""
        B = self.solution.B
        return B if self.clusters is None else self.clusters.spread(B)


@dataclass
class BakeContext:
    """What the stages share: the inputs, then each stage's products (None until it ran)."""

    meshes: list | None
    settings: BakeSettings
    lights: list
    world: np.ndarray | None
    cache: FormFactorCache | None
    progress: object
    cancelled: object
    stage: str = ""
    timings: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    patches: PatchSet | None = None
    clusters: Clusters | None = None          # small faces grouped: the solve's unknowns
    form_factors: CSR | None = None
    form_factor_source: str = ""
    direct: DirectLight | None = None        # exact direct light, or None ('hemicube' mode)
    direct_patch: np.ndarray | None = None   # (N, 3) radiance arriving directly at patch centres
    irradiance: np.ndarray | None = None     # (N, 3) W/m^2 direct irradiance at patch centres
    direct_source: np.ndarray | None = None  # (K, 3) exact path: direct light each unknown reflects
    given: bool = False                      # patches handed in ready: used as they are (not refined)
    sky_patch: np.ndarray | None = None      # (N, 3) the world's part of direct_patch (exact path)
    source: np.ndarray | None = None         # (N, 3) the solve's source term
    reflected: np.ndarray | None = None      # (N, 3) exact path: the solve's reflected-only B
    solution: Solution | None = None
    elements: PatchSet | None = None
    vertex_radiosity: np.ndarray | None = None
    error_estimate: object = None            # core.output.estimate.ErrorEstimate (estimate stage)
    forecast: object = None                  # core.runtime.forecast.Forecast (said before the form factors)
    _meshes_key: bytes | None = None         # :meth:`meshes_key`, once a bake
    ahead: dict = field(default_factory=dict)   # name -> background.Ahead: work started at the bake's start

    def meshes_key(self) -> bytes:
        """:func:`.elements.meshes_key` of the meshes, hashed once a bake (the patch and the
        vertex stages key their cached geometry on it)."""
        if self._meshes_key is None:
            self._meshes_key = meshes_key(self.meshes)
        return self._meshes_key

    @property
    def unknowns(self):
        """What the solve is for: the clusters, or the patches themselves (both have centers,
        normals, areas, rho, emission, owner)."""
        return self.patches if self.clusters is None else self.clusters

    def to_unknowns(self, per_patch):
        """(K, ...) area-weighted mean per cluster of a per-patch array (itself without clusters).
        A (P, k) array by a bincount per band (``Clusters.area_mean``, the same sums bit for bit
        as ``np.add.at``'s, about ten times faster; a relight asks twice)."""
        if self.clusters is None:
            return per_patch
        if np.ndim(per_patch) == 2:
            return self.clusters.area_mean(per_patch, self.patches.areas)
        return self.clusters.mean(per_patch, self.patches.areas)

    def to_patches(self, per_unknown):
        """(N, ...) per patch of a per-unknown array."""
        return per_unknown if self.clusters is None else self.clusters.spread(per_unknown)

    def say(self, fraction, message=""):
        """Report progress of the running stage."""
        if self.progress is not None:
            self.progress(self.stage, fraction, message)

    def check(self):
        if self.cancelled is not None and self.cancelled():
            raise Cancelled("cancelled")

    def run(self, name, stage):
        """Run one stage, timed under ``name``; stop here if the caller cancelled."""
        self.stage = name
        t = time.perf_counter()
        stage(self)
        self.say(1.0)
        self.timings[name] = time.perf_counter() - t
        self.check()

    def result(self) -> BakeResult:
        return BakeResult(self.patches, self.form_factors, self.solution, self.vertex_radiosity,
                          self.timings, self.form_factor_source, self.source, self.irradiance,
                          self.notes, self.elements, self.settings, self.clusters, self.error_estimate,
                          self.forecast)


def patch_stage(ctx) -> None:
    """Fill ``ctx.patches`` (unless given): the meshes cut to ``settings.patch_size``, and
    ``ctx.clusters``: small faces grouped into patches of about that size (None: none grouped)."""
    s = ctx.settings
    ctx.say(0.0, "cutting meshes into patches")
    if ctx.patches is None:
        # geometry only, cached: a relight re-reads the materials onto the same patches
        key = cache_key(ctx.meshes_key(), ("patches", s.patch_size, s.group_faces, s.group_angle))
        pieces, clusters = cached(ctx.cache, key, lambda: _cut(ctx.meshes, s, lambda: mesh_faces(ctx)))
        ctx.patches = pieces.with_mesh_materials(ctx.meshes)
        ctx.clusters = None if clusters is None else clusters.with_materials(ctx.patches)
    elif s.group_faces:
        ctx.clusters = group_pieces(ctx.patches, s.patch_size, s.group_angle)
    n = len(ctx.unknowns)
    if n > s.max_patches:
        raise PatchError(f"a patch size of {s.patch_size} makes {n} patches, more than the limit "
                         f"of {s.max_patches}: use a larger patch size (and a detail size for "
                         "sharp output)" + ("" if s.group_faces else ", or group small faces"))
    gb = form_factor_gb(n, s)
    if gb > s.max_memory_gb:
        size = s.patch_size or 0.0
        hint = (f": use a larger patch size (now {size:.3g}; {2 * size:.3g} needs about "
                f"{form_factor_gb(n / 4, s):.2g} GB)") if size else ": set a patch size"
        raise PatchError(f"{n} patches need about {gb:.2g} GB of form factors, more than the "
                         f"memory budget of {s.max_memory_gb:g} GB{hint}")
    grouped = "" if ctx.clusters is None else f" grouped from {len(ctx.patches)} faces"
    ctx.say(1.0, f"{n} patches{grouped}; form factors at most {1024 * gb:.0f} MB")


def _cut(meshes, s, faces=None):
    """(patches, clusters or None): the meshes cut to the patch size and small faces grouped.
    ``faces()``: ``build_patches(meshes)``, the meshes' faces as they are (the bake's, built once
    a bake: :func:`.elements.mesh_faces`), the patches where the size cuts no face."""
    faces = faces or (lambda: build_patches(meshes, None))
    try:
        whole = keeps_faces_whole(meshes, s.patch_size)
    except PatchError:
        whole = False                         # build_patches says what is wrong, in its order
    pieces = faces() if whole else build_patches(meshes, s.patch_size)
    clusters = group_pieces(pieces, s.patch_size, s.group_angle) if s.group_faces else None
    if clusters is None:
        # cut along where surfaces stand on others, as the output is (core/mesh/contact.py): a patch
        # across a partition off the patch grid lit the dark side with the lit side's light
        # (0.5% of the lit floor on average, 2.9% at worst; now 0). Faces cut into one patch
        # (the user's own, finer than the patches) stay whole
        pieces = cut_along_contacts(pieces, faces())
    return pieces, clusters


def form_factor_gb(n, settings) -> float:
    """Upper bound of F's memory for ``n`` patches in GB: a row holds at most one entry per
    hemi-cube pixel (or ray) and per patch, 8 bytes each (float32 value, int32 column)."""
    per_row = settings.rays_per_patch if settings.method == "embree_stochastic" else 3 * settings.resolution ** 2
    return n * min(n, per_row) * 8 / 2 ** 30


def solve_stage(ctx) -> None:
    """Fill ``ctx.solution``: B = S + rho F B per band (:func:`.solvers.solve`). On the exact
    direct path the solve carries reflected light only; the solution reports B = E + R."""
    s, p = ctx.settings, ctx.unknowns
    computed = np.zeros(len(p), bool)
    computed[receivers_needed(p)] = True
    ctx.say(0.0, s.solver)
    sol = solve(ctx.form_factors, p.rho, ctx.source, s.solver, s.tolerance, s.max_iterations,
                areas=p.areas, cancelled=ctx.cancelled, computed=computed,
                progress=lambda fr: ctx.say(fr, ""))
    bound = sol.error_bound
    ctx.say(1.0, f"{sol.iterations} iterations, residual {sol.residual:.2e}, error below {bound:.1e}"
            + ("" if sol.converged else " (NOT converged: raise max iterations)"))
    if not sol.converged:
        ctx.notes.append(f"solver stopped after {sol.iterations} iterations with a relative error "
                         f"up to {bound:.1e}, above the tolerance {s.tolerance:g}: raise max "
                         "iterations")
    energy = scene_energy(ctx, sol.energy, computed) if sol.energy else sol.energy
    if ctx.direct is not None:
        ctx.reflected = sol.B
        sol = replace(sol, B=sol.B + p.emission, extra={**sol.extra, "reflected_only": True})
    ctx.solution = replace(sol, energy=energy)


def lamp_power(light) -> np.ndarray:
    """(3,) what a lamp sends out, in the balance's units (radiance x area: watts / pi), or
    None for a sun (unbounded: it is counted as what reaches the patches). Point: P; spot: P
    times its cone's share of the sphere, ``(1 - cos(size/2)) (1 - blend/2) / 2`` (Cycles'
    smoothstep integrates to half the blend band); area: P (one-sided). A point or spot with a
    radius and soft falloff is counted by its far field (the disk model gives a little less
    near it)."""
    if isinstance(light, SunLight):
        return None
    share = 1.0
    if isinstance(light, SpotLight):
        share = 0.5 * (1 - np.cos(0.5 * light.spot_size)) * (1 - 0.5 * light.spot_blend)
    return light.power_w * share * np.asarray(light.color, float) / np.pi


def _suns_at(ctx):
    """(N, 3) radiance arriving from the suns alone at the patches, sampled exactly as the
    direct light was (same points, seed and ray streams: the other lamps are kept in the list,
    dark and without shadow rays), or None without a sun."""
    s, p = ctx.settings, ctx.patches
    if not any(isinstance(li, SunLight) for li in ctx.lights):
        return None
    only = [li if isinstance(li, SunLight) else replace(li, power_w=0.0, cast_shadows=False)
            for li in ctx.lights]

    def at(points=None, normals=None, where=""):
        return direct_irradiance(p, only, points=points, normals=normals, samples=s.light_samples,
                                 seed=s.light_seed, cancelled=ctx.cancelled) / np.pi
    if ctx.direct is None:
        return at()
    grouped = None if ctx.clusters is None else ctx.clusters.sizes[ctx.clusters.of] > 1
    return patch_average(p, s.patch_light_points, at, grouped)


def _world_and_direct(ctx, a, D, computed):
    """(what the world delivers, what the direct light delivers, what of it is absorbed) per band,
    radiance x area: on the exact path the world is in ``D`` (``ctx.sky_patch`` its part);
    otherwise it comes through F's sky fractions and is reflected by the solve."""
    p, u = ctx.patches, ctx.unknowns
    if ctx.sky_patch is not None:
        return (a * ctx.sky_patch).sum(axis=0), (a * D).sum(axis=0), (a * (1 - p.rho) * D).sum(axis=0)
    world = world_reflected = np.zeros(3)
    if ctx.world is not None and np.any(np.asarray(ctx.world) > 0) and ctx.form_factors.sky is not None:
        sky = np.where(computed, ctx.form_factors.sky, 0.0)
        world = (u.areas * sky).sum() * np.asarray(ctx.world, float)
        world_reflected = (u.areas[:, None] * u.rho * sky[:, None] * np.asarray(ctx.world, float)).sum(axis=0)
    recv = (a * D).sum(axis=0) + world
    return world, recv, (a * (1 - p.rho) * D).sum(axis=0) + world - world_reflected


def scene_energy(ctx, solved: dict, computed) -> dict:
    """The whole scene's power balance per band, radiance x area (x pi for watts):
    ``emitted = absorbed + escaped``, where the solve's own balance (``solved``, kept under
    'solve') counts only what goes through F.

    What is counted: emitted is the emissive faces' light (both sides when two-sided, on the
    exact path; what the solve emits on the 'hemicube' path), the lamps' power
    (:func:`lamp_power`) and, for the unbounded sources (suns, the world), the light they deliver
    to the patches. Light arriving directly (``ctx.direct_patch``, or the lamps' irradiance on
    the 'hemicube' path) is absorbed at (1 - rho) and reflected into the solve (less what the
    parts of patches the scene cannot see reflect: absorbed where it lands); what the direct
    light does not deliver to any patch's front escapes (through openings into the world, or
    onto back faces), as does what the solve's rows do not see. 'direct' holds the direct
    light's own emitted / received / absorbed / escaped; ``imbalance`` is relative, as in
    :func:`.residual.energy_balance` (the direct part balances by construction: its escape is
    measured as what did not arrive, checked against closed forms in tests/core/test_hard_cases.py)."""
    p, u = ctx.patches, ctx.unknowns
    # the areas over three bands: the same products as p.areas[:, None]'s, without broadcasting
    # a (N, 1) factor along the short axis (5x as long)
    a = np.repeat(np.asarray(p.areas, dtype=np.float64)[:, None], 3, axis=1)
    zero = np.zeros(3)
    if ctx.direct is not None:
        D = ctx.direct_patch
        e = p.emitting()
        sides = 2.0 if ctx.direct.two_sided else 1.0
        surf = sides * (a[e] * p.emission[e]).sum(axis=0)
    else:
        D = zero[None] if ctx.irradiance is None else ctx.irradiance / np.pi
        surf = zero
    lamps = [lamp_power(li) for li in ctx.lights]
    lamps = sum((w for w in lamps if w is not None), zero)
    sun = _suns_at(ctx)
    sun = zero if sun is None else (a * sun).sum(axis=0)
    world, recv, absorbed = _world_and_direct(ctx, a, D, computed)
    if ctx.direct_source is not None:
        # what the parts of patches the scene cannot see reflect (a ceiling above a lamp's back)
        # lands on what encloses them, not in the solve (light/stage.py, _seen_weight)
        absorbed = absorbed + (u.areas[:, None] * (ctx.to_unknowns(p.rho * D) - ctx.direct_source)).sum(axis=0)
    emitted = surf + lamps + sun + world
    direct = {"emitted": emitted, "received": recv, "absorbed": absorbed, "escaped": emitted - recv}
    # the 'hemicube' path's emitters are the solve's own source
    own = zero if ctx.direct is not None else (u.areas[:, None] * u.emission).sum(axis=0)
    total = {"emitted": emitted + own,
             "absorbed": absorbed + np.asarray(solved["absorbed"]),
             "escaped": direct["escaped"] + np.asarray(solved["escaped"])}
    miss = np.abs(total["emitted"] - total["absorbed"] - total["escaped"])
    with np.errstate(invalid="ignore", divide="ignore"):
        imb = np.where(total["emitted"] > 0, miss / total["emitted"], 0.0)
    return {**{k: v.tolist() for k, v in total.items()}, "imbalance": float(np.max(imb)),
            "direct": {k: v.tolist() for k, v in direct.items()}, "solve": solved}


# Every stage in order: its name, the function that runs it, and its usual share of a bake's time
# in percent (for progress bars; the form factors dominate). A new stage is one entry here.
STAGE_LIST = (("patches", patch_stage, 3), ("refine", refine_stage, 2),
               ("form_factors", form_factor_stage, 65), ("direct", direct_stage, 8),
               ("solve", solve_stage, 4), ("vertices", vertex_stage, 13), ("estimate", estimate_stage, 2))
STAGES = tuple((name, stage) for name, stage, _ in STAGE_LIST)
STAGE_SHARES = {name: share for name, _, share in STAGE_LIST}


def _madvise_switch():
    """NumPy's switch for asking the kernel for huge pages on its large arrays (private in
    NumPy 1.x and 2.x alike), or None where it has none."""
    for name in ("numpy._core.multiarray", "numpy.core.multiarray"):
        try:
            module = importlib.import_module(name)
        except ImportError:
            continue
        switch = getattr(module, "_set_madvise_hugepage", None)
        if switch is not None:
            return switch
    return None


@contextmanager
def small_pages():
    """NumPy's arrays on ordinary pages for the length of a bake, as before afterwards.

    NumPy asks Linux for transparent huge pages (madvise) on every array of 4 MB or more. Where
    the kernel serves them on request (``/sys/kernel/mm/transparent_hugepage/enabled`` =
    'madvise', a common default), a bake, which makes thousands of such short-lived
    temporaries, ran clearly slower with them, on one worker and on two (faulting 2 MB pages
    in, zeroed and compacted for, cost more than they saved). Where the kernel gives huge pages always, or never, this changes nothing."""
    switch = _madvise_switch()
    before = switch(False) if switch is not None else None
    try:
        yield
    finally:
        if switch is not None:
            switch(before)


def bake(meshes, settings: BakeSettings | None = None, *, progress=None, cancelled=None,
         lights=(), world=None, cache: FormFactorCache | None = None,
         patches: PatchSet | None = None) -> BakeResult:
    """Run every stage of :data:`STAGES`. ``progress(stage, fraction, message)``; ``cancelled()
    -> bool`` (raises :class:`.progress.Cancelled`). ``lights``: core.light.lamps light objects;
    ``world``: (3,) radiance. ``cache``: a :class:`.cache.FormFactorCache`; a hit skips the
    form-factor work. ``patches``: a ready PatchSet (then ``meshes`` is not cut again, nor the
    patches refined: a relight hands back the refined patches of a first bake)."""
    settings = settings or BakeSettings()
    settings.validate()
    if meshes is not None:
        settings = settings.resolved(meshes)
    elif "auto" in (settings.patch_size, settings.element_size):
        raise SettingsError("'auto' sizes need the meshes")
    # without a cache to keep, one for this bake alone: stages that ask for the same
    # geometry-only work (the direct light at the output vertices) do it once
    ctx = BakeContext(meshes, settings, list(lights or ()), world, cache if cache is not None else FormFactorCache(),
                      progress, cancelled, patches=patches, given=patches is not None)
    t0 = time.perf_counter()
    with small_pages(), one_blas_thread(), kept_heap():   # (runtime/native.py says why)
        ctx.check()
        try:
            # geometry a later stage reads, made on a core the first stages leave idle
            ctx.ahead["elements"] = start_elements(ctx)
            for name, stage in STAGES:
                ctx.run(name, stage)
        finally:                                 # taken, or left by a stop: terminated
            for pending in ctx.ahead.values():
                if pending is not None:
                    pending.close()
    ctx.timings["total"] = time.perf_counter() - t0
    return ctx.result()
