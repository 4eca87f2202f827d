"""The add-on inside Blender as a test drives it: installed as an extension the way Blender does
it (a local extension repository whose directory holds a ``hemicube_radiosity`` link to the
repository root), enabled and disabled with errors raised, its submodules, the selection, and the
operator's modal loop driven without a window.

``install_extension_repo`` puts the repository under ``BLENDER_USER_RESOURCES``, which
``tests/conftest.py`` points at a fresh temp dir before bpy is first imported."""
from __future__ import annotations

import importlib
import os

from . import ROOT

REPO_MODULE = "hr_test_repo"
ADDON_MODULE = f"bl_ext.{REPO_MODULE}.hemicube_radiosity"


def _raise(ex):
    raise ex


def install_extension_repo(bpy):
    """A USER extension repository whose only extension is this source folder."""
    prefs = bpy.context.preferences.extensions
    if prefs.repos.get(REPO_MODULE) is None and all(r.module != REPO_MODULE for r in prefs.repos):
        repo_dir = os.path.join(os.environ["BLENDER_USER_RESOURCES"], "dev_repo")
        os.makedirs(repo_dir, exist_ok=True)
        link = os.path.join(repo_dir, "hemicube_radiosity")
        if not os.path.exists(link):
            os.symlink(ROOT, link, target_is_directory=True)
        prefs.repos.new(name=REPO_MODULE, module=REPO_MODULE, custom_directory=repo_dir, source="USER")


def enable_addon():
    import addon_utils

    return addon_utils.enable(ADDON_MODULE, default_set=True, handle_error=_raise)


def disable_addon():
    import addon_utils

    addon_utils.disable(ADDON_MODULE, default_set=True, handle_error=_raise)


def sub(addon, name):
    """The add-on's submodule ``name`` (``"blender.bake"``) as Blender imported it."""
    return importlib.import_module(f"{addon.__name__}.{name}")


def lit_cornell_box(addon, bpy):
    """The demo's Cornell box with a 30 W point lamp at (1, 0.7, 1.2), the session's cache cleared
    (what a relight test starts from): (objects, lamp object, their names)."""
    sub(addon, "blender.bake").clear_session_cache()
    objs = sub(addon, "blender.demo").build_cornell_box(bpy.context)
    bpy.ops.object.light_add(type="POINT", location=(1.0, 0.7, 1.2))
    lamp = bpy.context.active_object
    lamp.data.energy = 30.0
    return objs, lamp, [o.name for o in objs]


def select(bpy, objs):
    """Select exactly ``objs``, the first one active (none active when empty)."""
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    for o in objs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objs[0] if objs else None


# coarse, and the patches are the baked mesh (no detail size): a bake of seconds
MODAL_BAKE = dict(patch_size=0.25, resolution=32, element_size=0.0)


class _FakeUI:
    """The window-manager/workspace calls the modal loop makes, recorded (no window headless)."""

    def __init__(self):
        self.progress, self.status, self.timers_removed, self.ended = [], [], 0, False

    def progress_update(self, v):
        self.progress.append(v)

    def progress_end(self):
        self.ended = True

    def event_timer_remove(self, timer):
        self.timers_removed += 1

    def status_text_set(self, text):
        self.status.append(text)


def modal_run(addon, bpy, objs, cancel_first, settings=MODAL_BAKE):
    """Drive the operator's modal loop (worker thread + timer events) with a recording UI."""
    import threading
    import time
    import types

    ops = sub(addon, "blender.ui.operators")
    bake = sub(addon, "blender.bake")
    cls = ops.OBJECT_OT_radiosity_bake
    ui = _FakeUI()

    class Ctx:
        window_manager = ui
        workspace = ui

        def __getattr__(self, name):
            return getattr(bpy.context, name)

    op = types.SimpleNamespace(reports=[])
    op.report = lambda level, msg: op.reports.append((level, msg))
    for name in ("_work", "_progress", "_finish", "_cleanup", "_report_done"):
        setattr(op, name, types.MethodType(getattr(cls, name), op))
    bake.clear_session_cache()  # earlier tests baked this geometry: make the form factors run
    op._job = bake.BakeJob.prepare(bpy.context, objs, bake.BakeSettings(**settings))
    op._cancel = threading.Event()
    op._state = ops.worker_state()
    op._timer = object()
    op._thread = threading.Thread(target=op._work)
    if cancel_first:
        esc = types.SimpleNamespace(type="ESC", value="PRESS")
        assert cls.modal(op, Ctx(), esc) == {"RUNNING_MODAL"}
    op._thread.start()
    timer = types.SimpleNamespace(type="TIMER", value="NOTHING")
    for _ in range(6000):
        ret = cls.modal(op, Ctx(), timer)
        if ret != {"RUNNING_MODAL"}:
            break
        time.sleep(0.01)
    return ret, op, ui
