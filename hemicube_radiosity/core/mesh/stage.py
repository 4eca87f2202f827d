"""The ``patches`` stage: the meshes cut into patches of the patch size (or kept whole where
they are finer), small faces grouped into clusters, cut along contact lines, and the bake
refused early when the patches or their form factors would not fit the limits.

Reads ``ctx.meshes`` and ``ctx.settings``; fills ``ctx.patches`` (materials read onto the cached
geometry, so a relight re-reads them) and ``ctx.clusters`` (None where no faces are grouped).
"""
from __future__ import annotations

import math

from ..runtime.cache import cache_key, cached
from .clusters import group_pieces, piece_materials
from .backs import backs_of_pieces, cutters
from .contact import cut_along_contacts
from .elements import mesh_faces
from .limits import CLUSTER_SPAN, passing_size, patches_about, pieces_at_least
from .patches import PatchError
from .subdivide import build_patches, keeps_faces_whole


def patch_stage(ctx) -> None:
    """Fill ``ctx.patches`` (unless given): the meshes cut to ``settings.patch_size``, and
    ``ctx.clusters``: small faces grouped into patches of about that size (None: none grouped)."""
    s = ctx.settings
    ctx.say(0.0, "cutting meshes into patches")
    if ctx.patches is None:
        # geometry only, cached: a relight re-reads the materials onto the same patches
        key = cache_key(ctx.meshes_key(), ("patches", s.patch_size, s.group_faces, s.group_angle))
        pieces, clusters = cached(ctx.cache, key, lambda: cut_patches(ctx.meshes, s, lambda: mesh_faces(ctx)))
        ctx.patches = pieces.with_mesh_materials(ctx.meshes)
        ctx.clusters = None if clusters is None else clusters.with_materials(ctx.patches)
    elif s.group_faces:
        ctx.clusters = group_pieces(ctx.patches, s.patch_size, s.group_angle)
    n = len(ctx.unknowns)
    if n > patch_limit(s):
        raise PatchError(_refusal(None if ctx.given else ctx.meshes, s, n, ""))
    gb = form_factor_gb(n, s)
    grouped = "" if ctx.clusters is None else f" grouped from {len(ctx.patches)} pieces"
    ctx.say(1.0, f"{n} patches{grouped}; form factors at most {1024 * gb:.0f} MB")


def cut_patches(meshes, s, faces=None):
    """(patches, clusters or None): the meshes cut to the patch size and small faces grouped.
    ``faces()``: ``build_patches(meshes)``, the meshes' faces as they are (the bake's, built once
    a bake: :func:`.elements.mesh_faces`), the patches where the size cuts no face."""
    faces = faces or (lambda: build_patches(meshes, None))
    try:
        whole = keeps_faces_whole(meshes, s.patch_size)
    except PatchError:
        whole = False                         # build_patches says what is wrong, in its order
    pieces = faces() if whole else build_patches(meshes, s.patch_size)
    clusters = group_pieces(pieces, s.patch_size, s.group_angle, piece_materials(pieces, meshes),
                            [m.size_scale for m in meshes], backs_of_pieces(meshes, pieces)) \
        if s.group_faces else None
    if clusters is None:
        # cut along where surfaces stand on others, as the output is (core/mesh/contact.py): a patch
        # across a partition off the patch grid lit the dark side with the lit side's light
        # (0.5% of the lit floor on average, 2.9% at worst; now 0). Faces cut into one patch
        # (the user's own, finer than the patches) stay whole
        cutting = faces()
        pieces = cut_along_contacts(pieces, cutting, cuts=cutters(meshes, cutting))
    return pieces, clusters


def form_factor_gb(n, settings) -> float:
    """Upper bound of F's memory for ``n`` patches in GB: a row holds at most one entry per
    hemi-cube pixel (or ray) and per patch, 8 bytes each (float32 value, int32 column)."""
    return n * min(n, _row_entries(settings)) * 8 / 2 ** 30


def _row_entries(settings) -> int:
    """The most entries a row of F holds: a hemi-cube's pixels, or the stochastic rays."""
    return settings.rays_per_patch if settings.method == "embree_stochastic" else 3 * settings.resolution ** 2


def patch_limit(settings) -> int:
    """The most patches a bake takes: ``max_patches``, and no more than the form factors'
    memory budget holds (:func:`form_factor_gb`)."""
    per_row = _row_entries(settings)
    entries = settings.max_memory_gb * 2 ** 30 / 8
    by_memory = math.isqrt(int(entries)) if entries <= per_row ** 2 else int(entries // per_row)
    return int(min(settings.max_patches, by_memory))


def _limit_name(settings, n) -> str:
    if n > settings.max_patches:
        return f"the limit of {settings.max_patches:,} (Max Patches)"
    return (f"the {patch_limit(settings):,} whose form factors fit the memory budget of "
            f"{settings.max_memory_gb:g} GB (about {form_factor_gb(n, settings):.2g} GB)")


def _refusal(meshes, s, n, about) -> str:
    """The message refusing ``n`` patches at ``s.patch_size``, naming a size that passes,
    measured by cutting the meshes at it (``meshes`` None: patches handed in, nothing to cut)."""
    size = s.patch_size or 0.0
    msg = f"a patch size of {size:.3g} makes {about}{int(n):,} patches, more than {_limit_name(s, n)}"
    limit = patch_limit(s)
    found = None
    if meshes is not None and size:
        def count(s2):
            if pieces_at_least(meshes, s2.patch_size) > 50 * limit:
                return math.inf
            pieces, clusters = cut_patches(meshes, s2)
            return len(pieces if clusters is None else clusters)
        found = passing_size(meshes, s, limit, count)
    if found is not None:
        msg += f": a patch size of {found[0]:.3g} makes {found[1]:,}"
    else:
        msg += ": use a larger patch size"
    if not s.group_faces:
        msg += " (or group small faces)"
    return msg + "; a detail size keeps the output sharp"


def check_before_cutting(meshes, s) -> None:
    """Refuse sizes that make far too many patches or output elements, counted from the faces'
    edges and areas before anything is cut (:mod:`.limits`): the patches when even the largest
    clusters could not bring them under :func:`patch_limit`, the elements when they are more
    than ``max_elements`` at least."""
    if meshes is None:
        return
    if s.patch_size:
        about = patches_about(meshes, s.patch_size, s.group_faces)
        if about > CLUSTER_SPAN * patch_limit(s):
            raise PatchError(_refusal(meshes, s, about, "about "))
    if s.uses_elements():
        at_least = pieces_at_least(meshes, s.element_size)
        if at_least > s.max_elements:
            need = float(s.element_size) * math.sqrt(at_least / s.max_elements) * 1.1
            raise PatchError(f"a detail size of {s.element_size:.3g} cuts the scene into at least "
                             f"{int(at_least):,} output elements, more than the limit of "
                             f"{s.max_elements:,} (Max Details): use a detail size of {need:.3g} or more")
