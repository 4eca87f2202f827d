"""Grouped emitters drawing their shadow rays' targets from keys of their own
(:func:`hemicube_radiosity.core.light.emitters.emitter_transport`'s ``group_keys``, which
:func:`hemicube_radiosity.core.output.shine.shine` passes): a group's transport is the same,
bit for bit, whatever other groups there are. Drawn from one stream for all, every group's
targets moved when one group came or went: the few targets of a lamp's glow on a ceiling, seen
alike from a whole far floor, moved it 0.8% (tests/core/test_hard_cases.py, a block sunk
deeper into the floor)."""
from __future__ import annotations

import numpy as np

from hemicube_radiosity.core import builtin_scenes as scenes
from hemicube_radiosity.core.light.emitters import emitter_transport, vertex_frames
from hemicube_radiosity.core.mesh.subdivide import build_patches
from hemicube_radiosity.core.rays import occluder


def test_a_groups_targets_do_not_move_when_another_group_goes():
    """The Cornell box's ceiling patches as groups of 3 shining on its vertices, the blocks
    casting their shadows: without its first group, the others' transports are unchanged with
    keys; from one stream some change (the check can fail)."""
    box = build_patches(scenes.cornell_box(), 0.25)
    x, n, _ = vertex_frames(box)
    em = np.flatnonzero(box.centers[:, 1] > box.verts[:, 1].max() - 1e-6)          # the ceiling
    em = em[box.emission[em].max(axis=1) == 0]                                    # not the lamp
    groups = np.arange(em.size) // 3
    keys = np.arange(1, groups.max() + 2, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    kw = dict(scene=occluder(box), samples=4)
    rest = groups > 0
    for k, k_rest, same in ((keys, keys[1:], True), (None, None, False)):
        T = emitter_transport(box, x, n, em, groups=groups, group_keys=k, **kw)
        T_rest = emitter_transport(box, x, n, em[rest], groups=groups[rest] - 1, group_keys=k_rest, **kw)
        assert T.shape[1] == groups.max() + 1 >= 4
        unlit = emitter_transport(box, x, n, em, groups=groups, scene=None, samples=4)
        assert ((T > 0) & (T < 0.999 * unlit)).any()                              # shadows there
        assert np.array_equal(T_rest, T[:, 1:]) == same
