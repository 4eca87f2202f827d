# SPDX-License-Identifier: GPL-3.0-or-later
"""Bake settings: one definition used by the scene's property group (the panel) and the operator."""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from ..core.pipeline import BakeSettings
from .bake import DIRECT_ITEMS, METHOD_ITEMS, OUTPUT_ITEMS, SOLVER_ITEMS

__all__ = ["setting_annotations", "SETTING_NAMES", "RadiositySettings", "register", "unregister"]


_D = BakeSettings()  # defaults come from the core, chosen by the benchmark


def setting_annotations():
    """Fresh property definitions (Blender needs one set per class)."""
    return {
        "auto_size": BoolProperty(
            name="Automatic Sizes", default=True,
            description="Patch size = the scene's diagonal / 14 and detail size = a third of it "
                        "(the benchmark's best trade-off at any scale); off: use the sizes below"),
        "patch_size": FloatProperty(
            name="Patch Size", default=0.25, min=0.0, soft_max=10.0, precision=3, unit="LENGTH",
            description="Target edge length of a radiosity patch; 0 keeps every face as one patch"),
        "resolution": IntProperty(
            name="Hemi-cube Resolution", default=_D.resolution, min=2, soft_min=8, max=2048, soft_max=512, step=2,
            description="Pixels along a side of the hemi-cube's top face (even)"),
        "method": EnumProperty(name="Method", items=METHOD_ITEMS, default="HEMICUBE",
                               description="How form factors are computed"),
        "rays_per_patch": IntProperty(name="Rays per Patch", default=512, min=1, soft_max=65536,
                                      description="Rays per patch for the stochastic Embree method"),
        "direct": EnumProperty(name="Direct Light", items=DIRECT_ITEMS, default="EXACT",
                               description="How light from emitters reaches the surfaces"),
        "element_size": FloatProperty(
            name="Detail Size", default=0.08, min=0.0, soft_max=10.0, unit="LENGTH", precision=3,
            description="Cut the baked mesh finer than the patches (0: the patches are the baked mesh). "
                        "Direct light is exact at every vertex; bounced light comes from the patches"),
        "gather_rays": IntProperty(
            name="Gather Rays", default=_D.gather_rays, min=0, soft_max=4096,
            description="With a detail size: gather bounced light at every vertex with this many rays "
                        "(0: interpolate it from the patches). Needs Embree"),
        "direct_samples": IntProperty(name="Shadow Rays", default=16, min=1, soft_max=1024,
                                      description="Shadow rays per point and emitting face "
                                                  "(exact direct light)"),
        "solver": EnumProperty(name="Solver", items=SOLVER_ITEMS, default="GAUSS_SEIDEL",
                               description="Iterative solver for the radiosity equation"),
        "tolerance": FloatProperty(name="Tolerance", default=1e-4, min=1e-10, max=1.0, precision=6,
                                   description="Stop when the relative residual falls below this"),
        "max_iterations": IntProperty(name="Max Iterations", default=200, min=1, soft_max=10000,
                                      description="Give up after this many sweeps (or shots)"),
        "output_mode": EnumProperty(name="Output", items=OUTPUT_ITEMS, default="COPY",
                                    description="Where the result goes"),
        "attribute_name": StringProperty(name="Attribute", default="Radiosity", maxlen=63,
                                         description="Name of the FLOAT_COLOR corner attribute"),
        "exposure": FloatProperty(name="Exposure", default=0.0, soft_min=-10.0, soft_max=10.0,
                                  description="Stops: written values are radiance x 2^exposure "
                                              "(0 keeps radiance units, nothing is clamped)"),
        "use_lights": BoolProperty(
            name="Lamps and World", default=True,
            description="Light objects and the world's background light the scene, in Cycles' units"),
        "cache_dir": StringProperty(
            name="Cache Folder", default="", subtype="DIR_PATH",
            description="Form factors depend on geometry only and are kept for this session; "
                        "with a folder they are also saved there and reused across sessions"),
        "include_others": BoolProperty(
            name="Other Visible Meshes", default=True,
            description="Visible meshes that are not selected take part as occluders and emitters "
                        "(they get no result)"),
    }


SETTING_NAMES = tuple(setting_annotations())


class RadiositySettings(bpy.types.PropertyGroup):
    __annotations__ = setting_annotations()


def register():
    bpy.utils.register_class(RadiositySettings)
    bpy.types.Scene.hemicube_radiosity = PointerProperty(type=RadiositySettings)


def unregister():
    del bpy.types.Scene.hemicube_radiosity
    bpy.utils.unregister_class(RadiositySettings)
