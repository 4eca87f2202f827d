# SPDX-License-Identifier: GPL-3.0-or-later
"""One bake as three steps shared by the operator (exec and modal) and the CLI.

``BakeJob.prepare`` reads the scene (main thread, bpy), ``job.run`` runs the pure-NumPy core (any
thread, no bpy; progress/cancel hooks), ``job.write`` writes Blender data (main thread). A
cancelled or failed ``run`` leaves the scene exactly as it was: nothing is written before
``write``. Settings are the core's :class:`BakeSettings` (``core/settings.py``); user-facing
problems are :class:`core.runtime.errors.RadiosityError`.
"""
from __future__ import annotations

import dataclasses
import re
import sys
import time

import bpy

from ..core.runtime.cache import FormFactorCache
from ..core.runtime.errors import RadiosityError
from ..core.runtime.forecast import SAID as FORECAST_SAID
from ..core.runtime.notes import grouped, help_url
from ..core.pipeline import BakeSettings, bake
from ..core.rays import clear_ray_cache, embree_available
from .read import scene as read
from .read.visibility import render_visible_objects
from . import in_place, write

__all__ = ["BakeJob", "StagePrinter", "resolve_objects", "other_meshes", "session_cache",
           "clear_session_cache"]


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
    """Forget cached form factors, transports and ray scenes (the add-on is disabled)."""
    _SESSION_CACHE.clear()
    clear_ray_cache()


def _source_of(ob):
    """A baked copy stands for its source object."""
    name = ob.get(write.SOURCE_KEY)
    if name is not None:
        return bpy.data.objects.get(name)
    return ob


def _mesh_sources(objects, skip=()):
    """The distinct mesh objects that ``objects`` stand for (a baked copy stands for its
    source), in order, leaving out the names in ``skip``."""
    out, seen = [], set(skip)
    for ob in objects:
        ob = _source_of(ob)
        if ob is None or ob.type not in read.GEOMETRY_TYPES or ob.name in seen:
            continue
        seen.add(ob.name)
        out.append(ob)
    return out


def resolve_objects(objects):
    """Objects to bake from a selection (meshes, and text, curves, surfaces and metaballs, read as
    the meshes Blender evaluates them to): baked copies map to their sources, no duplicates."""
    return _mesh_sources(objects)


def other_meshes(context, baked):
    """Meshes a render shows that are not baked (what the render sees is what the bake uses,
    whatever the viewport hides). A baked copy stands for its source (hidden by the bake), so a
    partial re-bake still sees the rest of the scene's geometry and materials. A particle
    emitter whose own mesh renders do not show (Show Emitter off in renders) is left out; its
    particles' instances are read with the instances (:mod:`.read.instances`)."""
    shown = [o for o in render_visible_objects(context.view_layer, read.GEOMETRY_TYPES)
             if not (o.is_instancer and not o.show_instancer_for_render)]
    return _mesh_sources(shown, {o.name for o in baked})


class StagePrinter:
    """progress(stage, fraction, message) -> one stdout line per stage when it ends (its last
    message and duration), and for long stages a line with % and ETA at most every ``interval``
    seconds. Call :meth:`finish` after the last stage."""

    NAMES = {"form_factors": "form factors", "direct": "direct light"}

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
        if message.startswith(FORECAST_SAID):     # the time a bake expects: before the work, at once
            self._line(f"{self.NAMES.get(stage, stage)}: {message}")
            return
        if message:
            self._message = message
        if fraction < 1.0 and now - self._last >= self.interval:
            self._last = now
            self._line(f"{self.NAMES.get(stage, stage)}: {message or f'{100 * fraction:.0f}%'}")


class BakeJob:
    def __init__(self, scene_input, settings: BakeSettings):
        self.scene_input = scene_input
        self.settings = settings
        self.cache = None
        self.result = None
        self.written = []
        self.lightmaps = []          # one record per lightmap written (target 'lightmap')
        self.notes = list(scene_input.notes())
        self.timings = {}

    @classmethod
    def prepare(cls, context, objects, settings: BakeSettings | None = None, cache=None):
        """Read the scene. ``objects``: the selection (objects that are not geometry are ignored).
        Raises :class:`RadiosityError` before any work when the result could not be written as
        the settings ask (:func:`.read.scene.check_writable`)."""
        settings = settings or BakeSettings()
        settings.validate()
        if settings.method.startswith("embree") and not embree_available():
            raise RadiosityError("the Embree method needs the 'embreex' Python package; "
                                 "install it or choose Hemi-cube")
        targets = resolve_objects(objects)
        if not targets:
            makers = [o.name for o in objects if o.instance_type == "COLLECTION" and o.instance_collection]
            if makers:                   # an Empty instancing a collection, alone
                raise RadiosityError(read.instancers_only(makers))
            raise RadiosityError("no mesh object selected (select meshes, text, curves or metaballs)")
        write_notes = read.check_writable(targets, settings)   # refuse now, not after the work
        others = other_meshes(context, targets) if settings.include_others else []
        # instances take part with the other meshes, or as part of their selected instancer
        instancers = None if settings.include_others else {_source_of(o).name for o in objects
                                                           if _source_of(o) is not None}
        depsgraph = context.evaluated_depsgraph_get()
        cache = cache if cache is not None else session_cache(settings.cache_dir)
        t = time.perf_counter()
        scene_input = read.read_scene(depsgraph, targets, others, instancers, cache)
        light_notes = []
        if settings.use_lights:
            from .read.lights import read_lights

            lights, world, light_notes = read_lights(depsgraph)
            scene_input.lights, scene_input.world = tuple(lights), world
        job = cls(scene_input, settings)
        job.notes += write_notes + light_notes
        job.cache = cache
        job.timings["read"] = time.perf_counter() - t
        return job

    def run(self, progress=None, cancelled=None):
        """The core bake; no bpy calls (safe in a worker thread). Raises core Cancelled."""
        self.result = bake(self.scene_input.meshes, self.settings, progress=progress,
                           cancelled=cancelled, lights=self.scene_input.lights,
                           world=self.scene_input.world, cache=self.cache)
        self.notes += list(self.result.notes)
        self.timings.update(self.result.timings)
        return self.result

    def write(self, context, progress=None):
        t = time.perf_counter()
        s = self.settings
        if progress:
            progress("write", 0.0, "writing")
        if s.output_mode == "in_place":
            self.written, notes = in_place.write_in_place(context, self.scene_input, self.result,
                                                       s.attribute_name, s.exposure)
            self.notes += notes
        elif s.target == "lightmap":
            from .lightmap import write_lightmaps

            self.written, self.lightmaps, notes = write_lightmaps(context, self.scene_input, self.result, s)
            self.notes += notes
        else:
            self.written = write.write_copies(context, self.scene_input, self.result,
                                              s.attribute_name, s.exposure, s.keep_textures)
        self.timings["write"] = time.perf_counter() - t
        if s.target == "lightmap" and s.output_mode != "in_place":
            # the lightmaps' texels (the bake read at every texel: the direct light again, the
            # rest located among the elements) are most of it, not the files: a stage of their own
            texels = sum(r.get("texel_seconds", 0.0) for r in self.lightmaps)
            self.timings["texels"] = texels
            self.timings["write"] = max(self.timings["write"] - texels, 0.0)
        if progress:
            what = (f"{len(self.lightmaps)} lightmap(s)" if s.target == "lightmap"
                    else f"attribute '{s.attribute_name}'")
            progress("write", 1.0, f"{len(self.written)} object(s), {what}")
            if hasattr(progress, "finish"):
                progress.finish()
        return self.written

    def messages(self):
        """The notes as a person reads them (:func:`core.runtime.notes.grouped`): warnings
        first, one line per kind naming the objects, materials or lights it concerns."""
        return grouped(self.notes)

    def counts(self) -> dict:
        """What the bake solved and wrote: ``faces`` of the meshes read (baked and others),
        ``patches_solved`` (the unknowns: grouped faces count once), ``pieces`` (what was cut
        and drawn), ``output_vertices`` (the output mesh's vertices, whose colours are written)."""
        r = self.result
        return {"faces": int(sum(m.face_offsets.size - 1 for m in self.scene_input.meshes)),
                "patches_solved": int(r.unknowns), "pieces": int(len(r.patches)),
                "output_vertices": int(len(r.elements.verts))}

    def summary(self):
        r, c = self.result, self.counts()
        estimate = "" if r.error_estimate is None else f", {r.error_estimate.describe()}"
        faces = f"{c['faces']:,} face" + ("" if c["faces"] == 1 else "s")
        return (f"Radiosity: {c['patches_solved']:,} patches solved from {faces}, "
                f"{c['output_vertices']:,} output vertices{estimate}; {r.solution.iterations} "
                f"iterations, residual {r.solution.residual:.1e}, {r.timings['total']:.1f} s")

    def report(self, **extra) -> dict:
        """Everything a pipeline wants to know about the bake, JSON-ready: the settings as used
        ('auto' sizes in scene units), every stage's time, counts (also per object), convergence,
        energy balance, the estimated error (with ``estimate_error``, else None), objects, notes,
        plus ``extra``. ``warnings`` and ``notes`` are the grouped lines (:meth:`messages`),
        ``note_lines`` every line as each reader and stage said it."""
        r, messages = self.result, self.messages()
        rep = {
            "settings": dataclasses.asdict(r.settings),
            "timings": {k: float(v) for k, v in self.timings.items()},
            "patches": int(len(r.patches)),
            "solved": int(r.unknowns),
            "elements": int(len(r.elements)),
            "per_object": {k: v for k, v in _with_notes(_per_object(r), self.notes).items()
                           if not _INSTANCE.match(k)},
            "nonzeros": int(r.form_factors.nnz),
            "iterations": int(r.solution.iterations),
            "residual": float(r.solution.residual),
            "converged": bool(r.solution.converged),
            "energy": _jsonable(r.solution.energy),
            "error_estimate": None if r.error_estimate is None else r.error_estimate.as_dict(),
            "forecast": None if r.forecast is None else r.forecast.as_dict(),
            "form_factor_source": r.form_factor_source,
            "objects": [o.name for o in self.scene_input.objects if o.bake],
            "occluders": [o.name for o in self.scene_input.objects if not o.bake and not _INSTANCE.match(o.name)],
            "instances": _instances(self.scene_input.objects),
            "written": [o.name for o in self.written],
            "lightmaps": list(self.lightmaps),
            **self.counts(),
            "warnings": list(messages.warnings),
            "help": {t: help_url(t) for t in messages.topics},
            "notes": list(messages.notes),
            "note_lines": [str(n) for n in self.notes],
        }
        rep.update(extra)
        return rep


def _per_object(r) -> dict:
    """{object name: {"patches": n, "elements": m, "solved": k, "vertices": v, "patch_size": s,
    "detail_size": d}}:
    how finely each object was cut (after refinement where the light changes abruptly), solved
    (the patches its grouped faces make, each counted with the object of its first face) and
    written, and the sizes it was cut at (an object far larger than the scene gets its own:
    core/mesh/sizes.py)."""
    import numpy as np

    names = r.patches.object_names
    front = r.fronts() if len(r.back_of) == len(names) else np.arange(len(names))
    n = len(names)
    # an object's back (its open faces turned around: core/mesh/backs.py) counts with the object
    p = np.bincount(front[r.patches.owner], minlength=n)
    e = np.bincount(front[r.elements.owner], minlength=n)
    k = np.bincount(front[r.clusters.owner if r.clusters is not None else r.patches.owner], minlength=n)
    polys = r.elements.polys
    vert_owner = np.full(len(r.elements.verts), -1, np.int64)
    corner = polys >= 0
    vert_owner[polys[corner]] = np.broadcast_to(front[r.elements.owner][:, None], polys.shape)[corner]
    v = np.bincount(vert_owner[vert_owner >= 0], minlength=n)
    sizes = [r.object_sizes(i) for i in range(n)]
    return {name: {"patches": int(p[i]), "elements": int(e[i]), "solved": int(k[i]),
                   "vertices": int(v[i]), "patch_size": sizes[i][0], "detail_size": sizes[i][1]}
            for i, name in enumerate(names) if front[i] == i}


# an instance's source is named after its instancer: "Scatter [instance 3]" (read/scene.py)
_INSTANCE = re.compile(r"^(.*) \[instance \d+\]$")


def _instances(objects) -> dict:
    """{instancer: how many of its instances took part} (one entry per instancer, not per
    instance: a scatter of 20,000 is one line)."""
    out = {}
    for o in objects:
        m = _INSTANCE.match(o.name)
        if m:
            out[m.group(1)] = out.get(m.group(1), 0) + 1
    return out


def _with_notes(per_object, notes) -> dict:
    """``per_object`` with each object's own first warning, else its first note, as ``note``
    (None: nothing said of it; lines of its materials are said of the material)."""
    from ..core.runtime.notes import subject_and_kind

    first = {}
    for n in notes:
        subject, _, warn = subject_and_kind(n)
        for name in (subject, (subject or "").strip("'")):
            if name in per_object and (name not in first or (warn and not first[name][0])):
                first[name] = (warn, str(n))
    return {k: {**v, "note": first.get(k, (False, None))[1]} for k, v in per_object.items()}


def _jsonable(x):
    import numpy as np

    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    return x
