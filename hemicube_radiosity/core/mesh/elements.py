"""The output mesh's geometry: the meshes' own faces, and the elements they are cut into.

The output mesh is the patches themselves, or (``settings.element_size`` finer than the patches)
*elements*: the input meshes cut to the detail size, then along where surfaces stand on others
(:func:`.contact.cut_along_contacts`, so no element straddles a wall's foot). Geometry only,
cached under :func:`meshes_key` (a relight re-reads only the materials). It lives here, before
the stages that read it: the patch stage shares :func:`mesh_faces`, the form factors' forecast
counts :func:`output_vertices_ahead`, the bake starts the cut at its start
(:func:`start_elements`) and the vertex stage takes it (:func:`cut_elements`).
"""
from __future__ import annotations

import numpy as np

from ..runtime.cache import cache_key, cached, geometry_key
from ..runtime.errors import RadiosityError
from ..runtime.background import Ahead
from ..runtime.parallel import resolve_workers
from .backs import cutters
from .contact import cut_along_contacts
from .patches import PatchSet, meshes_key
from .subdivide import build_patches, keeps_faces_whole

__all__ = ["meshes_key", "mesh_faces", "output_elements", "output_mesh_ahead", "output_vertices_ahead",
           "cut_elements", "start_elements"]


def _meshes_key(ctx):
    # the meshes hashed once a bake (the context keeps it) for the cached geometry; the
    # materials are read only onto the elements that are output
    return ctx.meshes_key() if hasattr(ctx, "meshes_key") else meshes_key(ctx.meshes)


def mesh_faces(ctx) -> PatchSet:
    """``build_patches(ctx.meshes)``: the meshes' own faces as patches, geometry only, built once
    a bake (kept in memory: the patches of a mesh finer than the patch size, its output elements
    where it is finer than the detail size, and the cutters of the cut along contacts)."""
    return cached(ctx.cache, cache_key(_meshes_key(ctx), ("faces",)), lambda: build_patches(ctx.meshes, None),
                  disk=False)


def _faces_whole(ctx, size) -> bool:
    """:func:`.subdivide.keeps_faces_whole` of the meshes at ``size``, once a bake (the start of the
    bake asks it for the detail size, and the elements again)."""
    return cached(ctx.cache, cache_key(_meshes_key(ctx), ("faces-whole", size)),
                  lambda: keeps_faces_whole(ctx.meshes, size), disk=False)


def output_elements(meshes, settings, cache=None) -> PatchSet:
    """The output mesh cut to ``settings.element_size``; its geometry is cached (a relight only
    re-reads reflectivity and emission from the meshes)."""
    key = cache_key(meshes_key(meshes), ("elements", settings.element_size))
    return cached(cache, key, lambda: build_patches(meshes, settings.element_size)).with_mesh_materials(meshes)


def _uncut_elements(ctx) -> PatchSet:
    """The meshes cut to the detail size (geometry only, cached), before the cut along contacts:
    the meshes' faces (:func:`mesh_faces`, built once a bake) where the detail size cuts none."""
    s = ctx.settings

    def make():
        if _faces_whole(ctx, s.element_size):
            return mesh_faces(ctx)
        return build_patches(ctx.meshes, s.element_size)
    return cached(ctx.cache, cache_key(_meshes_key(ctx), ("elements", s.element_size)), make)


def _refuse_elements(settings, count) -> None:
    if count > settings.max_elements:
        raise RadiosityError(f"a detail size of {settings.element_size} cuts the scene into {count} "
                             f"output elements, more than the limit of {settings.max_elements}: use a "
                             "larger detail size")


def output_vertices_ahead(ctx) -> int:
    """About how many vertices the output will have, before the form factors (the forecast's
    count, :mod:`.forecast`): the elements before their cut along contacts (a few more vertices
    come with the cut), or the patches when they are the output; refuses, as the vertex stage
    would, more elements than ``max_elements`` (the cut only adds)."""
    return len(output_mesh_ahead(ctx).verts)


def output_mesh_ahead(ctx) -> PatchSet:
    """The output mesh as :func:`output_vertices_ahead` counts it (the elements before their cut
    along contacts, or the patches); refuses more elements than ``max_elements``."""
    if not ctx.settings.uses_elements():
        return ctx.patches
    elements = _uncut_elements(ctx)
    if geometry_key(elements) == geometry_key(ctx.patches):
        return ctx.patches
    _refuse_elements(ctx.settings, len(elements))
    return elements


def _cut(meshes, elements, faces=None) -> PatchSet:
    """``elements`` cut along the contacts of the meshes' faces (:func:`.contact.cut_along_contacts`;
    ``faces``: ``build_patches(meshes)`` when the caller has it)."""
    faces = build_patches(meshes, None) if faces is None else faces
    return cut_along_contacts(elements.with_mesh_materials(meshes), faces, cuts=cutters(meshes, faces))


def cut_elements(ctx) -> PatchSet:
    """The output elements of the vertex stage: the meshes cut to the detail size, then along
    contacts (taken from :func:`start_elements`' process when it made them), or ``ctx.patches``
    when the detail size cuts nothing finer; refuses more than ``max_elements``."""
    s = ctx.settings
    ctx.say(0.0, f"cutting output elements of {s.element_size:g}")
    elements = _uncut_elements(ctx)
    if geometry_key(elements) == geometry_key(ctx.patches):
        return ctx.patches                    # the input is finer than the detail: its own faces
    # no element across a wall's foot: cut along where surfaces stand on others
    key = cache_key(_meshes_key(ctx), ("elements-cut", s.element_size))
    ahead = ctx.ahead.pop("elements", None) if hasattr(ctx, "ahead") else None
    if ahead is not None:                     # cut on a process of its own since the bake began
        cut = ahead.result(ctx.cancelled)
        if cut is not None and ctx.cache is not None and ctx.cache.get(key) is None:
            ctx.cache.put(key, cut)
    elements = cached(ctx.cache, key, lambda: _cut(ctx.meshes, elements, mesh_faces(ctx))).with_mesh_materials(ctx.meshes)
    _refuse_elements(s, len(elements))
    return elements


def start_elements(ctx):
    """The output elements' cut along contacts (:func:`cut_elements`: the bake's one long piece
    of geometry work done on one core) started on a forked process at the start of the bake,
    beside the patches, the refinement, the form factors and the direct light;
    :func:`cut_elements` takes it. A :class:`.background.Ahead`, or None: one worker, no
    elements, the elements cached (a relight forks nothing: forking costs more than it saves),
    or no face cut to the detail size (the elements are the input's faces: nothing to cut),
    no process forked. The process returns the same cut as
    :func:`cut_elements` makes."""
    s = ctx.settings
    if not s.uses_elements() or ctx.meshes is None or resolve_workers(s.workers) <= 1:
        return None
    if ctx.cache is not None and any(ctx.cache.get(cache_key(_meshes_key(ctx), (what, s.element_size))) is not None
                                     for what in ("elements", "elements-cut")):
        return None                           # made by a bake before (a relight): cut, or nothing to cut
    meshes, size = ctx.meshes, s.element_size
    try:
        if _faces_whole(ctx, size):
            # the elements are the faces: the process would only build them twice to say so,
            # on a core the form factors' workers want
            return None
    except RadiosityError:
        return None                           # unusable faces: the patch stage says which
    return Ahead.start(lambda: _cut(meshes, build_patches(meshes, size), build_patches(meshes, None)))
