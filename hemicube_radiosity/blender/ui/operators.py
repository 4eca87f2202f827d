# SPDX-License-Identifier: GPL-3.0-or-later
"""``object.radiosity_bake`` and ``object.radiosity_clear``.

Bake paths:
* ``execute`` (scripts, headless, redo): reads, runs the core and writes synchronously, printing
  one line per stage on stdout.
* ``invoke`` with a window: reads on the main thread, runs the core in a worker thread, and a
  timer-driven modal loop shows the progress bar and a status line; Esc cancels (the core stops
  at its next check and nothing is written, so the scene is unchanged); the result is written on
  the main thread when the worker finishes.

Properties not set explicitly take the scene's panel settings (``scene.hemicube_radiosity``), so
``bpy.ops.object.radiosity_bake(patch_size=0.5, method='EMBREE')`` overrides only what it names.
"""
from __future__ import annotations

import threading

import bpy

from ...core.pipeline import STAGE_SHARES, STAGES
from ...core.runtime.errors import RadiosityError
from ...core.runtime.progress import Cancelled
from ...core.runtime.notes import TOPICS, help_line, help_url
from ..bake import BakeJob, StagePrinter
from .props import SETTING_NAMES, setting_annotations, to_settings
from .. import write

__all__ = ["OBJECT_OT_radiosity_bake", "OBJECT_OT_radiosity_clear", "classes"]

_WRITE_SHARE = 3           # writing the result into the scene, in percent as STAGE_SHARES


def _stage_spans():
    """{stage: (start, end)} of the progress bar: the core's stages in order, each as wide as its
    usual share of a bake's time (``core.pipeline.STAGE_SHARES``), then the write."""
    shares = [(name, STAGE_SHARES[name]) for name, _ in STAGES] + [("write", _WRITE_SHARE)]
    total = sum(share for _, share in shares)
    spans, done = {}, 0
    for name, share in shares:
        spans[name] = (done / total, (done + share) / total)
        done += share
    return spans


_STAGE_SPAN = _stage_spans()
_PASS = {"MIDDLEMOUSE", "WHEELUPMOUSE", "WHEELDOWNMOUSE", "TRACKPADPAN", "TRACKPADZOOM",
         "MOUSEMOVE", "INBETWEEN_MOUSEMOVE", "NDOF_MOTION"}


def worker_state():
    """What the worker thread tells the modal loop: stage, fraction and message of the progress;
    a user-facing ``error`` line, or a ``bug`` (any other exception, raised on the main thread)."""
    return {"stage": STAGES[0][0], "fraction": 0.0, "message": "", "error": None, "bug": None,
            "cancelled": False}


def report_lines(job):
    """[(Blender report type, line)] after a bake: the grouped warnings first (WARNING), then
    the summary and the grouped notes (INFO), one report each, so the Info editor lists them
    one per line and the status bar shows the first warning."""
    m = job.messages()
    return ([({"WARNING"}, f"Radiosity: {w}") for w in m.warnings]
            + [({"INFO"}, f"Radiosity: {help_line(t)}") for t in m.topics] + [({"INFO"}, job.summary())]
            + [({"INFO"}, f"Radiosity note: {n}") for n in m.notes])


class OBJECT_OT_radiosity_bake(bpy.types.Operator):
    """Bake diffuse global illumination of the selected meshes into a colour attribute"""

    bl_idname = "object.radiosity_bake"
    bl_label = "Bake Radiosity"
    bl_options = {"REGISTER", "UNDO"}
    __annotations__ = setting_annotations()

    @classmethod
    def poll(cls, context):
        return context.mode == "OBJECT"

    # -- settings
    def _settings(self, context):
        s = context.scene.hemicube_radiosity
        explicit = {n for n in SETTING_NAMES if self.properties.is_property_set(n)}
        for name in SETTING_NAMES:
            if name not in explicit:
                setattr(self, name, getattr(s, name))
        # a script that passes a size means that size, not the automatic one
        if "auto_size" not in explicit and explicit & {"patch_size", "element_size"}:
            self.auto_size = False
        return to_settings(self)

    def _report_done(self, job, context=None):
        lines = report_lines(job)
        for kind, line in lines:
            self.report(kind, line)
        wm = getattr(context, "window_manager", None)
        # the popup needs a real window: the bpy module has one that is never drawn (and crashes)
        if not bpy.app.background and wm is not None and getattr(context, "window", None) is not None:
            def draw(menu, _context):          # the popup: warnings first, then the numbers
                for kind, line in lines:
                    menu.layout.label(text=line, icon="ERROR" if "WARNING" in kind else "INFO")
                for t in job.messages().topics:  # where the page says what to change
                    menu.layout.operator("wm.url_open", text=f"Troubleshooting: {TOPICS[t]}",
                                         icon="HELP").url = help_url(t)
            wm.popup_menu(draw, title="Radiosity bake", icon="ERROR" if job.messages().warnings else "INFO")

    # -- synchronous path
    def execute(self, context):
        printer = StagePrinter()
        try:
            job = BakeJob.prepare(context, context.selected_objects, self._settings(context))
            job.run(progress=printer)
            job.write(context, progress=printer)
        except RadiosityError as ex:
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}
        except Cancelled:
            self.report({"WARNING"}, "Radiosity bake cancelled; the scene is unchanged")
            return {"CANCELLED"}
        self._report_done(job, context)
        return {"FINISHED"}

    # -- modal path
    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            self._job = BakeJob.prepare(context, context.selected_objects, self._settings(context))
        except RadiosityError as ex:
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}
        self._cancel = threading.Event()
        self._state = worker_state()
        self._thread = threading.Thread(target=self._work, name="radiosity-bake", daemon=True)
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, 1000)
        self._thread.start()
        return {"RUNNING_MODAL"}

    def _progress(self, stage, fraction, message=""):
        self._state.update(stage=stage, fraction=fraction, message=message)

    def _work(self):
        try:
            self._job.run(progress=self._progress, cancelled=self._cancel.is_set)
        except Cancelled:
            self._state["cancelled"] = True
        except RadiosityError as ex:
            self._state["error"] = str(ex)
        except Exception as ex:  # a bug: raised again on the main thread, with its traceback
            self._state["bug"] = ex

    def modal(self, context, event):
        if event.type == "ESC" and event.value == "PRESS":
            self._cancel.set()
        if event.type == "TIMER":
            st = self._state
            lo, hi = _STAGE_SPAN.get(st["stage"], (0.0, 1.0))
            context.window_manager.progress_update(int(1000 * (lo + (hi - lo) * st["fraction"])))
            stage = st["stage"].replace("_", " ")
            text = ("Radiosity: cancelling..." if self._cancel.is_set() else
                    f"Radiosity: {stage} {100 * st['fraction']:.0f}% {st['message']}  (Esc to cancel)")
            if context.workspace is not None:
                context.workspace.status_text_set(text)
            if not self._thread.is_alive():
                return self._finish(context)
        if event.type in _PASS:
            return {"PASS_THROUGH"}
        return {"RUNNING_MODAL"}

    def _cleanup(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)

    def _finish(self, context):
        self._cleanup(context)
        st = self._state
        if st["cancelled"]:
            self.report({"WARNING"}, "Radiosity bake cancelled; the scene is unchanged")
            return {"CANCELLED"}
        if st["bug"] is not None:
            raise st["bug"]
        if st["error"]:
            self.report({"ERROR"}, st["error"])
            return {"CANCELLED"}
        try:
            self._job.write(context)
        except RadiosityError as ex:
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}
        self._report_done(self._job, context)
        return {"FINISHED"}

    def cancel(self, context):  # window closed / file loaded while running
        self._cancel.set()
        self._thread.join()
        self._cleanup(context)


class OBJECT_OT_radiosity_clear(bpy.types.Operator):
    """Delete the baked copies of the selected objects (or all) and show the originals again"""

    bl_idname = "object.radiosity_clear"
    bl_label = "Clear Radiosity Bake"
    bl_options = {"REGISTER", "UNDO"}

    all: bpy.props.BoolProperty(name="All", default=False,
                                description="Clear every baked copy, not just the selected ones")

    def execute(self, context):
        if self.all:
            names = {o.get(write.SOURCE_KEY) for o in bpy.data.objects if write.SOURCE_KEY in o}
        else:
            names = {o.get(write.SOURCE_KEY, o.name) for o in context.selected_objects}
        names.discard(None)
        n = len(write.copies_of(names))
        write.remove_bakes(names, unhide=True)
        self.report({"INFO"}, f"Removed {n} baked object(s)")
        return {"FINISHED"}


classes = (OBJECT_OT_radiosity_bake, OBJECT_OT_radiosity_clear)
