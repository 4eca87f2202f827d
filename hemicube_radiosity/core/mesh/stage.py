"""The ``patches`` stage: the meshes cut into patches of the patch size (or kept whole where
they are finer), small faces grouped into clusters, cut along contact lines, and the bake
refused early when the patches or their form factors would not fit the limits.

Reads ``ctx.meshes`` and ``ctx.settings``; fills ``ctx.patches`` (materials read onto the cached
geometry, so a relight re-reads them) and ``ctx.clusters`` (None where no faces are grouped).
"""
from __future__ import annotations

from ..runtime.cache import cache_key, cached
from .clusters import group_pieces, piece_materials
from .contact import cut_along_contacts
from .elements import mesh_faces
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
    clusters = group_pieces(pieces, s.patch_size, s.group_angle, piece_materials(pieces, meshes)) \
        if s.group_faces else None
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
