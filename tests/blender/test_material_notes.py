# SPDX-License-Identifier: GPL-3.0-or-later
"""Notes the material reader gives on real files: one per thing the artist may want to fix, not
one per default value. Blender's new Principled BSDF has Emission Color white at Emission Strength
0; every object of an imported or converted scene carries it (754 of bitterli_wooden_staircase's
775 objects noted it, burying the notes that matter)."""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tools import cycles_reference as cr  # noqa: E402
from hemicube_radiosity.blender.read import materials  # noqa: E402

pytestmark = pytest.mark.blender


def principled(color):
    m = bpy.data.materials.new("m")
    nt, out = cr.bare_node_tree(m)
    p = nt.nodes.new("ShaderNodeBsdfPrincipled")
    if color is not None:
        p.inputs["Emission Color"].default_value = (*color, 1.0)
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    return m


def test_default_principled_has_no_emission_note():
    cr.new_empty_scene()
    rho, em, notes = materials.material_rho_emission(principled(None))
    assert np.all(em == 0) and not any("Emission" in n for n in notes), notes


def test_emission_colour_at_strength_zero_is_noted():
    """An imported Ke colour at strength 0 (Blender 4.2's OBJ importer) still is."""
    cr.new_empty_scene()
    rho, em, notes = materials.material_rho_emission(principled((1.0, 0.5, 0.25)))
    assert np.all(em == 0)
    assert any("Emission Color (1, 0.5, 0.25) but Emission Strength 0" in n for n in notes), notes
