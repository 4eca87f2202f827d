"""Every bake setting, once: default, choices or limits, unit, label and help text.

:class:`BakeSettings` is the single source of the bake's settings. The Blender layer generates its
property group and the operator's properties from :func:`schema` (``blender/ui/props.py``), the CLI
its options (``blender/cli/parser.py``), and the report is ``dataclasses.asdict(settings)``. Adding a
setting is one field here (plus the code that reads it and its test); the panel, the operator, the
CLI and the report follow.

A field's ``metadata`` (see :func:`setting`):
    label, help     the panel's name and tooltip, the CLI's help text.
    group           which panel section shows it: 'main' (the top of the panel), 'patches',
                    'form_factors', 'light', 'solver', 'output'; None: not in the panel (CLI only).
    choices         ((value, label, description), ...) for an enum; values are lower case here,
                    upper case in Blender (``value.upper()``), as Blender's own enums are.
    min, max, soft_min, soft_max, step, precision, unit ('LENGTH' for world units)
    size            True for a size that may be 'auto' (follow the scene) or 0/None (one patch per
                    face / no finer output mesh); the panel shows it as a length under the shared
                    ``auto_size`` switch, with ``manual`` as the length it shows when that is off.
    cli             the CLI flag when it is not ``--field-name`` ("--no-lights" for a switch that
                    is on by default).
    off             for a switch that is on by default: what its CLI flag (which turns it off)
                    does, as its own sentence; ``help`` says what the switch does when on.
"""
from __future__ import annotations

from dataclasses import MISSING, asdict, dataclass, field, fields, replace

import numpy as np

from .runtime.errors import SettingsError

__all__ = ["BakeSettings", "Setting", "schema", "setting", "METHODS", "SOLVERS", "DIRECT_MODES", "QUALITY",
           "QUALITY_LEVELS",
           "OUTPUT_MODES", "OUTPUT_PASSES", "TARGETS", "AUTO_PATCHES_PER_DIAGONAL", "AUTO_ELEMENTS_PER_PATCH", "AUTO_SWITCH"]

AUTO_PATCHES_PER_DIAGONAL = 14.0   # 'auto' patch size: the scene's bounding-box diagonal / 14
AUTO_ELEMENTS_PER_PATCH = 3.0      # 'auto' detail size: a third of the patch size
AUTO_SWITCH = "auto_size"          # the panel's one switch for every 'auto' size

METHODS = (
    ("auto", "Automatic", "The hemi-cube rasteriser, or Embree's rays through the same pixels where "
     "a hemi-cube would draw so many polygons that the rays are faster (large scenes; needs "
     "embreex, else the rasteriser)"),
    ("hemicube", "Hemi-cube", "Rasterise a hemi-cube per patch in NumPy (the paper's method)"),
    ("embree", "Embree", "Cast rays through the hemi-cube pixel centres with Embree (needs embreex)"),
    ("embree_stochastic", "Embree (stochastic)", "Cosine-weighted random rays with Embree"),
)
SOLVERS = (
    ("gauss_seidel", "Gauss-Seidel", "Gathering, in-place sweeps"),
    ("jacobi", "Jacobi", "Gathering, whole-vector sweeps"),
    ("progressive", "Progressive", "Shooting: the patch with most unshot power first"),
)
DIRECT_MODES = (
    ("exact", "Exact", "Closed-form irradiance from each emitter times the visible fraction from "
     "shadow rays, at patch centres and again at every vertex (sharp shadows)"),
    ("hemicube", "Hemi-cube", "The paper's way: emitted light goes through the form factors too"),
)
OUTPUT_PASSES = (
    ("radiosity", "Radiosity", "Light leaving the surface: emission plus reflected light, the "
     "surface's colour included (Cycles' Diffuse bake with Color)"),
    ("lighting", "Lighting Only", "Light arriving at the surface, direct and indirect, without "
     "the surface's own colour (Cycles' Diffuse bake without Color): for textures multiplied at "
     "run time. Bounced light keeps the colours of the surfaces it came from"),
)
# Quality levels: what each sets of the detailed settings a user leaves at their defaults
# (:meth:`BakeSettings.with_quality`); 'patches' scales the automatic patch count per diagonal.
# Production is the defaults themselves. Measured (docs/performance.md, "Quality levels"):
# bench/real_scenes.py --levels, error against Cycles' 256-spp bake at its own corners.
QUALITY = {
    "draft": dict(patches=0.6, resolution=16, refine_levels=1, gather_rays=32, patch_light_points=1,
                  direct_samples=4, light_samples=4, sky_rays=64),
    "preview": dict(patches=0.8, resolution=24, refine_levels=2, gather_rays=64, patch_light_points=2,
                    direct_samples=8, light_samples=8, sky_rays=128),
    "production": dict(patches=1.0, resolution=32, refine_levels=3, gather_rays=128, patch_light_points=2,
                       direct_samples=16, light_samples=16, sky_rays=256),
    "final": dict(patches=1.4, resolution=48, refine_levels=3, gather_rays=256, patch_light_points=3,
                  direct_samples=32, light_samples=32, sky_rays=512),
}
QUALITY_LEVELS = (
    ("draft", "Draft", "A first look: about half Production's time (0.4-0.7x), its median error "
     "against Cycles 8-44% higher on the real-scene benchmark"),
    ("preview", "Preview", "About 0.7x Production's time (0.55-0.95x), its median error 0-20% higher"),
    ("production", "Production", "The defaults (the speed-against-error frontier of the "
     "benchmark): 1.1% RMS from Cycles' reference on the Stanford bunny (Cycles 64 spp: 1.3%), "
     "1.3-15 s per 10k triangles on 2 cores"),
    ("final", "Final", "1.4x the patches per diagonal, finer hemi-cubes and twice the rays: "
     "1.6-2.6x Production's time, its median error 0-14% lower (RMS at most 6% lower on the "
     "benchmark: what is left there is systematic)"),
)
TARGETS = (
    ("vertex_colours", "Vertex Colours", "A colour attribute at every face corner of the baked "
     "mesh (cut finer than the user's faces where the detail size asks)"),
    ("lightmap", "Lightmap", "An image through a lightmap UV map of the baked copy, which keeps "
     "the user's topology: OpenEXR (HDR) and a tone-mapped PNG; the copy shows it unlit"),
)
OUTPUT_MODES = (
    ("copy", "Baked Copy", "New objects in a 'Radiosity' collection carry the result; "
     "originals are hidden, never modified"),
    ("in_place", "In Place", "Write the colour attribute on the original meshes (modifies them)"),
)


def setting(default, label, help, group, **meta):
    """A dataclass field carrying its schema entry (see the module docstring)."""
    return field(default=default, metadata=dict(label=label, help=help, group=group, **meta))


@dataclass(frozen=True)
class Setting:
    """One entry of :func:`schema`: a field of :class:`BakeSettings` and its metadata."""

    name: str
    default: object
    type: type
    label: str
    help: str
    group: str | None
    meta: dict

    @property
    def choices(self):
        return self.meta.get("choices")

    @property
    def values(self):
        """The choices' values (lower case), or None."""
        return None if self.choices is None else tuple(c[0] for c in self.choices)


@dataclass
class BakeSettings:
    """What a bake does; see :func:`schema` for each field's label, help, limits and unit.

    Sizes are in world units ('auto' follows the scene: patches are its bounding-box diagonal / 14,
    details a third of that; 0 or None: one patch per input face / no finer output mesh).
    Defaults are the speed-against-error frontier of ``make bench`` (docs/performance.md).
    """

    # -- the top of the panel
    quality: str = setting("production", "Quality", "How finely the scene is cut and how many "
                           "rays it takes: each level sets the detailed settings left at their "
                           "defaults (a changed one overrides it)", "main", choices=QUALITY_LEVELS)
    output_mode: str = setting("copy", "Output", "Where the result goes", "main", choices=OUTPUT_MODES)
    use_lights: bool = setting(True, "Lamps and World", "Light objects and the world's background "
                               "light the scene, in Cycles' units", "main", cli="--no-lights",
                               off="Ignore light objects and the world: only emissive surfaces "
                               "light the scene")
    include_others: bool = setting(True, "Other Visible Meshes", "Visible meshes that are not "
                                   "selected take part as occluders and emitters (they get no "
                                   "result)", "main", cli="--no-others",
                                   off="Only the objects baked take part: other visible meshes "
                                   "neither occlude nor emit")
    # -- patches
    patch_size: float | str | None = setting(
        "auto", "Patch Size", "Target edge length of a radiosity patch; 0 keeps every face as one "
        "patch; auto: the scene's diagonal / 14", "patches", size=True, manual=0.25, min=0.0,
        soft_max=10.0, precision=3, unit="LENGTH")
    element_size: float | str | None = setting(
        "auto", "Detail Size", "Cut the baked mesh finer than the patches (0: the patches are the "
        "baked mesh; auto: a third of the patch size). Direct light is exact at every vertex; "
        "bounced light comes from the patches", "patches", size=True, manual=0.08, min=0.0,
        soft_max=10.0, precision=3, unit="LENGTH")
    group_faces: bool = setting(True, "Group Small Faces", "Faces smaller than the patch size (a "
                                "dense mesh) are grouped into patches of about the patch size, so "
                                "the solve follows how the light varies, not how finely the mesh "
                                "is modelled; direct light and the output stay on every face",
                                "patches", cli="--no-group-faces",
                                off="Keep every face as its own patch, however small (slow on a "
                                "dense mesh)")
    two_sided_reflection: bool = setting(True, "Two-Sided Surfaces", "Open surfaces (a single "
                                         "plane, a lamp panel, a leaf) reflect from both sides, "
                                         "as every surface does in Cycles; closed meshes pay "
                                         "nothing for it", "patches", cli="--one-sided-surfaces",
                                         off="Surfaces reflect from their front only (the "
                                         "paper's model): the back of a single plane is black")
    group_angle: float = setting(30.0, "Grouping Angle", "Faces whose normals differ by more "
                                 "than this many degrees are not grouped into one patch",
                                 "patches", min=1.0, max=90.0)
    refine_levels: int = setting(3, "Refinement Levels", "Split patches where the direct light "
                                 "changes abruptly across them (a shadow's edge, the foot of a "
                                 "block, a lamp close to a surface), up to this many times, each "
                                 "halving their size; 0: no refinement", "patches", min=0, max=6)
    max_patches: int = setting(20000, "Max Patches", "Stop with an error before cutting more "
                               "patches (form factors grow with their square)", "patches",
                               min=1, soft_max=100000)
    max_memory_gb: float = setting(8.0, "Memory Budget", "Stop before the form factors would "
                                   "need more than this many GB (estimated from the patch count "
                                   "and the hemi-cube's pixels)", "patches", min=0.01,
                                   soft_max=64.0)
    max_elements: int = setting(400000, "Max Details", "Stop with an error before cutting more "
                                "output elements", "patches", min=1, soft_max=4000000)
    # -- form factors
    method: str = setting("auto", "Method", "How form factors are computed", "form_factors",
                          choices=METHODS)
    workers: int = setting(0, "Workers", "Cores that compute form factors and per-vertex light "
                           "at once (0: every core, 1: one). On Linux form factors run in worker "
                           "processes forked from this one (elsewhere on threads), per-vertex "
                           "light on threads; the result is the same for any count",
                           "form_factors", min=0, soft_max=64)
    resolution: int = setting(32, "Hemi-cube Resolution", "Pixels along a side of the hemi-cube's "
                              "top face (even)", "form_factors", min=2, max=2048, soft_min=8,
                              soft_max=512, step=2)
    rays_per_patch: int = setting(512, "Rays per Patch", "Rays per patch for the stochastic Embree "
                                  "method", "form_factors", min=1, soft_max=65536)
    rotate_seed: int | None = setting(None, "Rotate Seed", "Rotate each hemi-cube about its normal "
                                      "at random with this seed (default: no rotation)", None, min=0)
    cache_dir: str = setting("", "Cache Folder", "Form factors depend on geometry only and are "
                             "kept for this session; with a folder they are also saved there and "
                             "reused across sessions", "form_factors", cli="--cache",
                             subtype="DIR_PATH")
    # -- light
    direct: str = setting("exact", "Direct Light", "How light from emitters reaches the surfaces",
                          "light", choices=DIRECT_MODES)
    two_sided_emission: bool = setting(True, "Two-Sided Emitters", "Emissive faces light both "
                                       "sides, as Cycles' Emission shader does (a lamp panel just "
                                       "under a ceiling lights the ceiling too); off: the front "
                                       "only, the paper's model. Needs exact direct light",
                                       "light", cli="--one-sided-emission",
                                       off="Emissive faces light their front only (the paper's "
                                       "model)")
    specular_bounce: bool = setting(True, "Specular Bounce", "Light that specular and metallic "
                                    "layers reflect (Cycles' glossy albedo) reaches the other "
                                    "surfaces: a metal or lacquer mirrors it (with Embree; a weak "
                                    "layer, or without Embree, spreads it as diffuse light), so a "
                                    "metal floor lights the room as in Cycles; the baked colour of "
                                    "the surface itself stays its diffuse part", "light", cli="--no-specular-bounce",
                                    off="Only diffuse reflectance bounces: light off metal and "
                                    "glossy layers is lost (the paper's model)")
    specular_rays: int = setting(1024, "Specular Rays", "Rays per glossy patch (its faces "
                                 "share them by area) that carry the light a metal or lacquer "
                                 "mirrors, with its direction (Specular Bounce; needs Embree)", "light", min=16, soft_max=65536)
    patch_light_points: int = setting(2, "Light Points per Patch", "Direct light for the solve "
                                      "is averaged over n x n points of each patch (1: its centre "
                                      "only, the paper's way; more: a patch next to a bright lamp "
                                      "gets its share of it, not all or nothing)", "light",
                                      min=1, max=8)
    direct_samples: int = setting(16, "Shadow Rays", "Shadow rays per point and emitting face "
                                  "(exact direct light)", "light", min=1, soft_max=1024)
    light_samples: int = setting(16, "Lamp Shadow Rays", "Shadow rays per point for lamps with a "
                                 "size (radius, angle, area); a point of zero size uses one",
                                 "light", min=1, soft_max=1024)
    sky_rays: int = setting(256, "Sky Rays", "Rays per point that look for the world (its light "
                            "is exact at every output vertex and patch point); an environment "
                            "texture's variation takes 4 times as many directions", "light", min=1,
                            soft_max=4096)
    light_seed: int = setting(0, "Lamp Seed", "Random seed of the lamps' shadow rays", None, min=0)
    gather_rays: int = setting(128, "Gather Rays", "With a detail size (or 'auto' finding the faces "
                               "too many to cut finer): gather bounced light at every vertex with "
                               "this many rays, or the Sky Rays where more and the world lights "
                               "the scene: the same rays find the world; a dense scene's faces half "
                               "as many (0: interpolate it from the patches). Needs Embree",
                               "light", min=0,
                               soft_max=4096)
    # -- solver
    solver: str = setting("gauss_seidel", "Solver", "Iterative solver for the radiosity equation",
                          "solver", choices=SOLVERS)
    tolerance: float = setting(1e-4, "Tolerance", "Stop when the relative residual falls below "
                               "this", "solver", min=1e-10, max=1.0, precision=6)
    max_iterations: int = setting(200, "Max Iterations", "Give up after this many sweeps (or "
                                  "shots)", "solver", min=1, soft_max=10000)
    # -- output
    estimate_error: bool = setting(False, "Estimate Error", "After the bake, run the output again "
                                   "with half the gather rays and at twice the detail size, and "
                                   "report how much it moved as the estimated error (about a third "
                                   "more time)", "output")
    output_pass: str = setting("radiosity", "Pass", "What the colour attribute holds", "output",
                               choices=OUTPUT_PASSES)
    keep_textures: bool = setting(True, "Keep Textures", "Baked copies of textured objects show "
                                  "their texture times the light arriving (a second attribute, "
                                  "'<Attribute> Light'), so a tiled floor keeps its pattern; the "
                                  "radiosity attribute is written too", "output",
                                  cli="--no-textures", off="Baked copies show the radiosity "
                                  "attribute only: a texture is its colour at each output corner")
    attribute_name: str = setting("Radiosity", "Attribute", "Name of the FLOAT_COLOR corner "
                                  "attribute", "output", cli="--attribute", maxlen=63)
    exposure: float = setting(0.0, "Exposure", "Stops: written values are radiance x 2^exposure "
                              "(0 keeps radiance units, nothing is clamped)", "output",
                              soft_min=-10.0, soft_max=10.0)
    view_transform: str = setting(
        "standard", "glTF View Transform", "How exported glTF maps the HDR bake into COLOR_0 "
        "(0..1, linear); the HDR values stay in _RADIANCE", "output", choices=(
            ("standard", "Standard", "Clamp to 0..1: a viewer shows what Blender's Standard view "
             "shows"),
            ("khronos_neutral", "Khronos PBR Neutral", "The Khronos PBR Neutral tone mapper, as "
             "Blender's view of that name"),
            ("agx", "AgX", "An AgX-like curve (the fit three.js and Filament use); close to "
             "Blender's AgX view, not identical")))

    target: str = setting("vertex_colours", "Target", "What the bake writes: vertex colours, or "
                          "a lightmap image through a UV map (the user's topology kept)", "output",
                          choices=TARGETS)
    lightmap_density: float = setting(32.0, "Lightmap Density", "Texels per world unit: a "
                                      "lightmap's side is this times the square root of its "
                                      "object's surface area (clamped to the maximum size)",
                                      "output", min=0.01, soft_max=1024.0)
    lightmap_max_size: int = setting(1024, "Lightmap Max Size", "Largest side of a lightmap, in "
                                     "texels", "output", min=8, max=16384)
    lightmap_uv: str = setting("", "Lightmap UV Map", "UV map the lightmap is read through; "
                               "empty: the mesh's second UV map, or one made on the baked copy "
                               "with Lightmap Pack (the user's mesh is never changed)", "output",
                               maxlen=63)
    lightmap_dir: str = setting("", "Lightmap Folder", "Where the lightmaps' .exr and .png go; "
                                "empty: a 'lightmaps' folder beside the saved .blend (the "
                                "command line: beside its first output)", "output",
                                subtype="DIR_PATH")

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_mapping(cls, mapping) -> "BakeSettings":
        """Settings from anything with the fields as keys or attributes: a dict, argparse's
        namespace, Blender's property group or operator. Missing fields keep their defaults;
        enum values may be upper case (Blender's); a size of 0 means None; the panel's
        ``auto_size`` switch, where present, turns every size to 'auto' (on) or to its length
        (off)."""
        get = mapping.get if isinstance(mapping, dict) else (lambda k, d=None: getattr(mapping, k, d))
        auto = get(AUTO_SWITCH, None)
        kw = {}
        for s in schema():
            v = get(s.name, MISSING)
            if v is MISSING:
                continue
            if s.choices is not None:
                v = str(v).lower()
            elif s.meta.get("size"):
                v = "auto" if auto else (None if v in (None, 0) or v == 0.0 else v)
            kw[s.name] = v
        return cls(**kw)

    def as_dict(self) -> dict:
        """Plain values (JSON-ready) for the report."""
        return asdict(self)

    # ------------------------------------------------------------------ checks
    def validate(self) -> None:
        """Raise :class:`SettingsError` naming the first setting outside its choices or limits."""
        for s in schema():
            v = getattr(self, s.name)
            if s.values is not None and v not in s.values:
                raise SettingsError(f"unknown {s.label.lower()} {v!r}; choose one of {', '.join(s.values)}")
            if s.meta.get("size"):
                if (isinstance(v, str) and v != "auto") or (not isinstance(v, str) and v is not None
                                                            and not (np.isfinite(v) and v >= 0)):
                    raise SettingsError(f"{s.label.lower()} must be >= 0 or 'auto', got {v!r}")
                continue
            if v is None or isinstance(v, (str, bool)):
                continue
            lo, hi = s.meta.get("min"), s.meta.get("max")
            if not np.isfinite(v) or (lo is not None and v < lo) or (hi is not None and v > hi):
                raise SettingsError(f"{s.label.lower()} must be in [{lo}, {hi}], got {v!r}")
        if self.method != "embree_stochastic" and self.resolution % 2:
            raise SettingsError(f"hemi-cube resolution must be an even number >= 2, got {self.resolution}")
        if self.target == "lightmap" and self.output_mode == "in_place":
            raise SettingsError("a lightmap is written on baked copies: choose the baked-copy "
                                "output, not in place")
        if self.uses_elements() and self.direct != "exact":
            raise SettingsError("finer output elements need direct='exact' (direct light at every "
                                "element vertex)")

    # ------------------------------------------------------------------ derived values
    def with_quality(self) -> "BakeSettings":
        """A copy with the quality level's values (:data:`QUALITY`) in every setting it names
        that is still at its default: a setting the user changed overrides the level."""
        level = QUALITY.get(self.quality, {})
        defaults = {s.name: s.default for s in schema()}
        return replace(self, **{k: v for k, v in level.items()
                                if k in defaults and getattr(self, k) == defaults[k]})

    def patches_per_diagonal(self) -> float:
        """The 'auto' patch size is the scene's diagonal / this (the quality level's share of
        :data:`AUTO_PATCHES_PER_DIAGONAL`)."""
        return AUTO_PATCHES_PER_DIAGONAL * QUALITY.get(self.quality, {}).get("patches", 1.0)

    def resolved(self, meshes) -> "BakeSettings":
        """A copy with 'auto' sizes turned into world units for ``meshes`` (core.mesh.patches.MeshInput)."""
        patch, element = self.patch_size, self.element_size
        if patch == "auto":
            from .mesh.sizes import auto_sizes
            patch = auto_sizes(meshes, self.patches_per_diagonal())[0]
        if element == "auto":
            element = patch / AUTO_ELEMENTS_PER_PATCH if patch else None
        if self.output_mode == "in_place":
            element = None
        return replace(self, patch_size=patch, element_size=element)

    def uses_elements(self) -> bool:
        """True when the output mesh is cut finer than the patches (never in place: there the
        user's own faces are the output)."""
        if not self.element_size or self.output_mode == "in_place":
            return False
        if self.element_size == "auto":
            return bool(self.patch_size)
        if self.patch_size == "auto":
            return True
        return not self.patch_size or self.element_size < self.patch_size

    def form_factor_key(self) -> tuple:
        """What shapes F (besides geometry): a change here recomputes, anything else re-solves."""
        if self.method == "embree_stochastic":
            return (self.method, int(self.rays_per_patch), self.rotate_seed)
        return (self.method, int(self.resolution), self.rotate_seed)


def _field_type(f):
    """The Python type of a field's value (bool, int, float, str; sizes are float)."""
    if f.metadata.get("size"):
        return float
    return type(f.default) if f.default is not None else int


_SCHEMA = tuple(Setting(f.name, f.default, _field_type(f), f.metadata["label"], f.metadata["help"],
                        f.metadata["group"], {k: v for k, v in f.metadata.items()
                                              if k not in ("label", "help", "group")})
                for f in fields(BakeSettings))


def schema() -> tuple:
    """Every setting, in the panel's order: a tuple of :class:`Setting`."""
    return _SCHEMA
