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

from .form_factors.glossy import GLOSSY_MIN
from .form_factors.stage import compute_form_factors, form_factor_stage, receivers_needed
from .light.stage import direct_stage, source_term
from .light.direct import DirectLight
from .mesh.backs import with_backs
from .mesh.clusters import Clusters
from .mesh.elements import meshes_key, output_elements, start_elements
from .mesh.patches import PatchSet
from .mesh.refine import refine_stage
from .mesh.sizes import fitted_detail, with_auto_scales
from .mesh.specular import with_specular_bounce
from .mesh.stage import check_before_cutting, patch_stage
from .output.estimate import estimate_stage
from .output.stage import vertex_stage
from .runtime.cache import FormFactorCache
from .runtime.errors import SettingsError
from .rays import embree_available
from .runtime.native import kept_heap, one_blas_thread
from .runtime.progress import Cancelled
from .settings import BakeSettings
from .solve.solvers import Solution
from .solve.stage import solve_stage
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
    size_scales: tuple = ()                   # per object: its sizes are the settings' times this (core.mesh.sizes)
    back_of: tuple = ()                       # per object: -1, or the object whose back it is (core.mesh.backs)
    back_faces: tuple = ()                    # per object: None, or (a back) the face of its front behind each face
    corner_radiosity: np.ndarray | None = None   # (N, 4, 3) per element corner where colours or light vary by corner
    corner_light: np.ndarray | None = None       # (N, 4, 3) the light arriving, where colours vary by corner
    direct: DirectLight | None = None            # the exact direct light, to light other points (lightmaps)
    vertex_direct: np.ndarray | None = None      # (V, 3) direct light arriving at the output vertices
    vertex_indirect: np.ndarray | None = None    # (V, 3) light arriving reflected at least once
    vertex_rho: np.ndarray | None = None         # (V, 3) reflectivity at the vertices (lighting pass: 1)
    corner_rho: np.ndarray | None = None         # (N, 4, 3) per element corner where colours vary by corner
    corner_direct: np.ndarray | None = None      # (N, 4, 3) direct light per corner, where corners are lit on their own
    corner_keep: np.ndarray | None = None        # (N, 4) the share of the vertex's indirect light each corner keeps

    def __post_init__(self):
        if self.elements is None:
            self.elements = self.patches

    def corner_values(self) -> np.ndarray:
        """(N, 4, 3) the output at every corner of ``elements`` (a triangle's fourth corner is its
        third): each corner's own value where the meshes' colours vary by corner (a texture) or
        a corner was lit on its own (a crease, :mod:`.output.crease`): ``corner_radiosity``;
        else its vertex's ``vertex_radiosity``."""
        if self.corner_radiosity is not None:
            return self.corner_radiosity
        return self.vertex_radiosity[self.elements.corner_ids()]

    def corner_lighting(self) -> np.ndarray | None:
        """(N, 4, 3) the light arriving at every corner of ``elements`` (radiance: irradiance / pi,
        without the surface's colour or emission), or None: kept only where the meshes' colours
        vary by corner (a texture), for a baked copy that multiplies its texture by it."""
        return self.corner_light

    def corner_parts(self) -> tuple | None:
        """(emission, reflectivity, direct, indirect), each (N, 4, 3) at every corner of
        ``elements``, with ``corner_values() == emission + reflectivity * (direct + indirect)``
        (to round-off): direct and indirect are the light arriving (radiance: irradiance / pi)
        straight from the sources and reflected at least once. With ``output_pass='lighting'``
        the reflectivity is 1 and the emission 0. None without the exact direct light (the
        paper's 'hemicube' path)."""
        if self.vertex_direct is None:
            return None
        cv = self.elements.corner_ids()
        rho = self.vertex_rho[cv] if self.corner_rho is None else self.corner_rho
        D = self.vertex_direct[cv] if self.corner_direct is None else self.corner_direct
        I = self.vertex_indirect[cv]
        if self.corner_keep is not None:          # a corner lit on its own (a crease, :mod:`.output.crease`)
            I = I * self.corner_keep[..., None]
        return self.corner_values() - rho * (D + I), rho, D, I

    def front_faces(self, owner, faces) -> np.ndarray:
        """(n,) int64 the faces of the object ``owner`` is (or is the back of) that ``faces`` (n,)
        of owner ``owner``'s mesh are, or lie behind."""
        faces = np.asarray(faces, dtype=np.int64)
        back = self.back_faces[owner] if owner < len(self.back_faces) else None
        return faces if back is None else np.asarray(back, dtype=np.int64)[faces]

    def owners_of(self, i) -> np.ndarray:
        """(k,) int64 the owners (``patches.owner``, ``elements.owner``) that hold object ``i``'s
        light: itself and its back, where open surfaces got one (:mod:`.mesh.backs`)."""
        return np.array([i] + [j for j, b in enumerate(self.back_of) if b == i], dtype=np.int64)

    def fronts(self) -> np.ndarray:
        """(M,) int64 for every owner the object it belongs to (a back: its front's index)."""
        return np.array([j if b < 0 else b for j, b in enumerate(self.back_of)], dtype=np.int64)

    @property
    def unknowns(self) -> int:
        """How many patches were solved for (clusters, or the patches themselves)."""
        return len(self.patches if self.clusters is None else self.clusters)

    def object_sizes(self, i) -> tuple:
        """(patch size, detail size) object ``i`` was cut at, in world units (None: not cut)."""
        k = self.size_scales[i] if i < len(self.size_scales) else 1.0
        s = self.settings
        return tuple(None if not isinstance(v, (int, float)) or not v else float(v) * k
                     for v in (s.patch_size, s.element_size))

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
    dense: bool = False                      # 'auto' found no detail size the elements' limit allows
                                             # (output.indirect.gathers_faces)
    sky_patch: np.ndarray | None = None      # (N, 3) the world's part of direct_patch (exact path)
    unbounded_patch: np.ndarray | None = None  # (N, 3) the suns' and maps' part of direct_patch (exact path)
    source: np.ndarray | None = None         # (N, 3) the solve's source term
    glossy: np.ndarray | None = None         # (N, 3) glossy albedo of the patches that mirror (form factors)
    specular: object = None                  # form_factors.glossy.Specular: what they mirror, or None
    lamps_mirrored: np.ndarray | None = None # (K, 3) lamps' light arriving off glossy patches (direct)
    reflected: np.ndarray | None = None      # (N, 3) exact path: the solve's reflected-only B
    solution: Solution | None = None
    elements: PatchSet | None = None
    vertex_radiosity: np.ndarray | None = None
    corner_radiosity: np.ndarray | None = None   # (N, 4, 3): textured or creased corners (output stage)
    corner_lighting: np.ndarray | None = None    # (N, 4, 3): the light arriving there (output stage)
    vertex_direct: np.ndarray | None = None      # (V, 3): the direct part of it (output stage)
    vertex_indirect: np.ndarray | None = None    # (V, 3): the part reflected at least once (output stage)
    vertex_rho: np.ndarray | None = None         # (V, 3): reflectivity there (output stage)
    corner_rho: np.ndarray | None = None         # (N, 4, 3): textured corners' reflectivity (output stage)
    corner_direct: np.ndarray | None = None      # (N, 4, 3): creased corners' own direct light (output stage)
    corner_keep: np.ndarray | None = None        # (N, 4): their share of the vertex's indirect light (output stage)
    gather_rays: object = None               # the final gather's (G, H) reader (output stage, output.above)
    gather_key: object = None                # what its rays depend on (output.above keys its table by it)
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
                          self.forecast, tuple(m.size_scale for m in self.meshes or ()),
                          tuple(getattr(m, "back_of", -1) for m in self.meshes or ()),
                          tuple(getattr(m, "back_faces", None) for m in self.meshes or ()),
                          self.corner_radiosity, self.corner_lighting, direct=self.direct,
                          vertex_direct=self.vertex_direct, vertex_indirect=self.vertex_indirect,
                          vertex_rho=self.vertex_rho, corner_rho=self.corner_rho,
                          corner_direct=self.corner_direct, corner_keep=self.corner_keep)


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


def _specular(meshes, notes) -> list:
    """``meshes`` ready for the specular bounce (:mod:`.mesh.specular`): metal and lacquer faces
    mirror their light through Embree's rays (:mod:`.form_factors.glossy`), or without Embree
    spread it as diffuse light, said in ``notes``."""
    directional = embree_available()
    if not directional and any(m.face_glossy is not None and np.max(m.face_glossy, initial=0) >= GLOSSY_MIN
                               for m in meshes):
        notes.append("Embree is not available: light off metal and glossy faces is spread as "
                     "diffuse light, without its direction")
    return with_specular_bounce(meshes, directional, GLOSSY_MIN)


def bake(meshes, settings: BakeSettings | None = None, *, progress=None, cancelled=None,
         lights=(), world=None, cache: FormFactorCache | None = None,
         patches: PatchSet | None = None) -> BakeResult:
    """Run every stage of :data:`STAGES`. ``progress(stage, fraction, message)``; ``cancelled()
    -> bool`` (raises :class:`.progress.Cancelled`). ``lights``: core.light.lamps light objects;
    ``world``: (3,) radiance. ``cache``: a :class:`.cache.FormFactorCache`; a hit skips the
    form-factor work. ``patches``: a ready PatchSet (then ``meshes`` is not cut again, nor the
    patches refined: a relight hands back the refined patches of a first bake)."""
    settings = (settings or BakeSettings()).with_quality()
    settings.validate()
    notes = []
    dense = False
    if meshes is not None:
        if settings.specular_bounce:             # light off metal reaches the rest
            meshes = _specular(meshes, notes)
        if settings.patch_size:                  # a ground plane around the scene: its own size
            meshes = with_auto_scales(meshes, settings.patches_per_diagonal(),
                                      None if settings.patch_size == "auto" else float(settings.patch_size))
        auto_detail = settings.element_size == "auto"
        settings = settings.resolved(meshes)
        if settings.two_sided_reflection:        # open surfaces reflect from both sides
            meshes = with_backs(meshes, settings.two_sided_emission, lights, world, cache=cache)
        if auto_detail and settings.element_size:   # as fine as the elements' limit allows
            settings = replace(settings, element_size=fitted_detail(
                meshes, settings.element_size, settings.patch_size, settings.max_elements))
            dense = settings.element_size is None     # the faces are the output, gathered
    elif "auto" in (settings.patch_size, settings.element_size):
        raise SettingsError("'auto' sizes need the meshes")
    # without a cache to keep, one for this bake alone: stages that ask for the same
    # geometry-only work (the direct light at the output vertices) do it once
    ctx = BakeContext(meshes, settings, list(lights or ()), world, cache if cache is not None else FormFactorCache(),
                      progress, cancelled, patches=patches, given=patches is not None, dense=dense)
    ctx.notes.extend(notes)
    t0 = time.perf_counter()
    with small_pages(), one_blas_thread(), kept_heap():   # (runtime/native.py says why)
        ctx.check()
        check_before_cutting(meshes if patches is None else None, settings)
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
