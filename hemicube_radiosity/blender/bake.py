# SPDX-License-Identifier: GPL-3.0-or-later
"""One bake as three steps shared by the operator (exec and modal) and the CLI.

``BakeJob.prepare`` reads the scene (main thread, bpy), ``job.run`` runs the pure-NumPy core (any
thread, no bpy; progress/cancel hooks), ``job.write`` writes Blender data (main thread). A
cancelled or failed ``run`` leaves the scene exactly as it was: nothing is written before
``write``.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import bpy

from ..core.cache import FormFactorCache
from ..core.patches import PatchError
from ..core.pipeline import BakeSettings, bake
from . import read, write

__all__ = ["BakeOptions", "BakeJob", "BakeError", "StagePrinter", "resolve_objects", "other_meshes",
           "session_cache", "clear_session_cache",
           "METHOD_ITEMS", "SOLVER_ITEMS", "OUTPUT_ITEMS"]

METHOD_ITEMS = (
    ("HEMICUBE", "Hemi-cube", "Rasterise a hemi-cube per patch in NumPy (the paper's method)"),
    ("EMBREE", "Embree", "Cast rays through the hemi-cube pixel centres with Embree (needs embreex)"),
    ("EMBREE_STOCHASTIC", "Embree (stochastic)", "Cosine-weighted random rays with Embree"),
)
DIRECT_ITEMS = (
    ("EXACT", "Exact", "Closed-form irradiance from each emitter times the visible fraction from "
     "shadow rays, at patch centres and again at every vertex (sharp shadows)"),
    ("HEMICUBE", "Hemi-cube", "The paper's way: emitted light goes through the form factors too"),
)
SOLVER_ITEMS = (
    ("GAUSS_SEIDEL", "Gauss-Seidel", "Gathering, in-place sweeps"),
    ("JACOBI", "Jacobi", "Gathering, whole-vector sweeps"),
    ("PROGRESSIVE", "Progressive", "Shooting: the patch with most unshot power first"),
)
OUTPUT_ITEMS = (
    ("COPY", "Baked Copy", "New objects with the patch mesh in a 'Radiosity' collection; "
     "originals are hidden, never modified"),
    ("IN_PLACE", "In Place", "Write the colour attribute on the original meshes (modifies them)"),
)


class BakeError(RuntimeError):
    """A user-facing problem; the message names the object where there is one."""


@dataclass
class BakeOptions:
    settings: BakeSettings = field(default_factory=BakeSettings)
    output_mode: str = "COPY"           # COPY | IN_PLACE
    attribute_name: str = "Radiosity"
    exposure: float = 0.0               # stops: values written are radiance * 2**exposure
    include_others: bool = True         # other visible meshes occlude/emit, are not written
    use_lights: bool = True             # lamps and the world light the scene (as in Cycles)
    cache_dir: str = ""                 # also keep form factors on disk here ("" = memory only)

    @classmethod
    def from_props(cls, p):
        """From the add-on's property group or the operator (same property names)."""
        s = BakeSettings(
            patch_size="auto" if p.auto_size else (float(p.patch_size) if p.patch_size > 0 else None),
            resolution=int(p.resolution),
            method=p.method.lower(),
            rays_per_patch=int(p.rays_per_patch),
            solver=p.solver.lower(),
            tolerance=float(p.tolerance),
            max_iterations=int(p.max_iterations),
        )
        if hasattr(s, "direct"):
            s.direct = p.direct.lower()
            s.direct_samples = int(p.direct_samples)
        # in place, the user's faces are the output: a finer detail size has nowhere to go
        s.element_size = ("auto" if p.auto_size else float(p.element_size) if p.element_size > 0 else None)
        if p.output_mode == "IN_PLACE":
            s.element_size = None
        s.gather_rays = int(p.gather_rays)
        return cls(s, p.output_mode, p.attribute_name, float(p.exposure), bool(p.include_others),
                   bool(p.use_lights), bpy.path.abspath(p.cache_dir) if p.cache_dir else "")


_SESSION_CACHE = {}


def session_cache(directory=""):
    """The add-on's form-factor cache for this Blender session (one per cache folder; "" keeps
    them in memory only). A relight (materials, emission, lamps, world) reuses form factors and
    the emitters' direct-light transport; a geometry change recomputes them."""
    cache = _SESSION_CACHE.get(directory)
    if cache is None:
        cache = _SESSION_CACHE[directory] = FormFactorCache(directory or None)
    return cache


def clear_session_cache():
    _SESSION_CACHE.clear()


def _source_of(ob):
    """A baked copy stands for its source object."""
    name = ob.get(write.SOURCE_KEY)
    if name is not None:
        return bpy.data.objects.get(name)
    return ob


def resolve_objects(objects):
    """Mesh objects to bake from a selection: baked copies map to their sources, no duplicates."""
    out, seen = [], set()
    for ob in objects:
        ob = _source_of(ob)
        if ob is None or ob.type != "MESH" or ob.name in seen:
            continue
        seen.add(ob.name)
        out.append(ob)
    return out


def other_meshes(context, baked):
    """Visible meshes that are not baked. A visible baked copy stands for its (hidden) source,
    so a partial re-bake still sees the rest of the scene's geometry and materials."""
    names = {o.name for o in baked}
    out = []
    for o in context.view_layer.objects:
        if o.type != "MESH" or not o.visible_get():
            continue
        src = _source_of(o)
        if src is None or src.type != "MESH" or src.name in names:
            continue
        names.add(src.name)
        out.append(src)
    return out


class StagePrinter:
    """progress(stage, fraction, message) -> one stdout line per stage when it ends (its last
    message and duration), and for long stages a line with % and ETA at most every ``interval``
    seconds. Call :meth:`finish` after the last stage."""

    NAMES = {"patches": "patches", "form_factors": "form factors", "solve": "solve",
             "direct": "direct light", "write": "write"}

    def __init__(self, stream=None, interval=5.0, prefix="radiosity"):
        self.stream = stream or sys.stdout
        self.interval = interval
        self.prefix = prefix
        self._stage = None
        self._start = self._last = 0.0
        self._message = ""

    def _line(self, text):
        print(f"{self.prefix}: {text}", file=self.stream, flush=True)

    def finish(self):
        if self._stage is not None:
            name = self.NAMES.get(self._stage, self._stage)
            dt = time.perf_counter() - self._start
            self._line(f"{name}: {self._message or 'done'} ({dt:.2f} s)")
        self._stage = None

    def __call__(self, stage, fraction, message=""):
        now = time.perf_counter()
        if stage != self._stage:
            self.finish()
            self._stage, self._start, self._last, self._message = stage, now, now, ""
        if message:
            self._message = message
        if fraction < 1.0 and now - self._last >= self.interval:
            self._last = now
            self._line(f"{self.NAMES.get(stage, stage)}: {message or f'{100 * fraction:.0f}%'}")


class BakeJob:
    def __init__(self, scene_input, options):
        self.scene_input = scene_input
        self.options = options
        self.cache = None
        self.result = None
        self.written = []
        self.notes = list(scene_input.notes())
        self.timings = {}

    @classmethod
    def prepare(cls, context, objects, options: BakeOptions, cache=None):
        """Read the scene. ``objects``: the selection (non-mesh objects are ignored)."""
        try:
            options.settings.validate()
        except ValueError as ex:
            raise BakeError(str(ex)) from None
        if options.settings.method.startswith("embree"):
            from ..core.embree_ff import embree_available

            if not embree_available():
                raise BakeError("the Embree method needs the 'embreex' Python package; "
                                "install it or choose Hemi-cube")
        targets = resolve_objects(objects)
        if not targets:
            raise BakeError("no mesh object selected")
        others = other_meshes(context, targets) if options.include_others else []
        depsgraph = context.evaluated_depsgraph_get()
        t = time.perf_counter()
        try:
            scene_input = read.read_scene(depsgraph, targets, others)
        except read.ReadError as ex:
            raise BakeError(str(ex)) from None
        light_notes = []
        if options.use_lights:
            from .lights import read_lights

            lights, world, light_notes = read_lights(depsgraph)
            scene_input.lights, scene_input.world = tuple(lights), world
        job = cls(scene_input, options)
        job.notes += light_notes
        job.cache = cache if cache is not None else session_cache(options.cache_dir)
        job.timings["read"] = time.perf_counter() - t
        return job

    def run(self, progress=None, cancelled=None):
        """The core bake; no bpy calls (safe in a worker thread). Raises core Cancelled."""
        try:
            self.result = bake(self.scene_input.meshes, self.options.settings, progress=progress,
                               cancelled=cancelled, lights=self.scene_input.lights,
                               world=self.scene_input.world, cache=self.cache)
        except PatchError as ex:
            raise BakeError(str(ex)) from None
        self.notes += list(self.result.notes)
        self.timings.update(self.result.timings)
        return self.result

    def write(self, context, progress=None):
        t = time.perf_counter()
        o = self.options
        if progress:
            progress("write", 0.0, "writing")
        try:
            if o.output_mode == "IN_PLACE":
                self.written, notes = write.write_in_place(context, self.scene_input, self.result,
                                                           o.attribute_name, o.exposure)
                self.notes += notes
            else:
                self.written = write.write_copies(context, self.scene_input, self.result,
                                                  o.attribute_name, o.exposure)
        except write.WriteError as ex:
            raise BakeError(str(ex)) from None
        self.timings["write"] = time.perf_counter() - t
        if progress:
            progress("write", 1.0, f"{len(self.written)} object(s), attribute '{o.attribute_name}'")
            if hasattr(progress, "finish"):
                progress.finish()
        return self.written

    def summary(self):
        r = self.result
        detail = "" if r.elements is r.patches else f" ({len(r.elements)} output elements)"
        return (f"Radiosity: {len(r.patches)} patches{detail}, {r.form_factors.nnz} form factors "
                f"({r.form_factor_source}), {r.solution.iterations} iterations, residual "
                f"{r.solution.residual:.1e}, {r.timings['total']:.1f} s")
