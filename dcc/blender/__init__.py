"""clothsr in Blender: runs clothsr on a USD shot, or on the current scene exported to USD, and
imports the fine cloth into the scene with the shot's frame range.

A panel in the 3D view's sidebar (tab "clothsr") holds the settings and the Run button. From
the UI the run goes on in a background thread, with progress in the status bar and Esc (or
the panel's Cancel) to stop it; a stopped run resumes when run again. Called from a script
(``bpy.ops.clothsr.run()``) or in a headless Blender, it runs to the end in the call. USD goes
through Blender's own ``pxr``; clothsr comes from the wheel bundled in this extension.
"""

import os
import pathlib
import sys
import tempfile
import threading

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, PointerProperty, StringProperty

FABRICS = [(f, f.capitalize(), f"clothsr's {f} preset") for f in ("silk", "cotton", "denim", "leather")]


def _blender_usd():
    """Blender's own ``pxr`` made importable: a Blender built as a Python module (PyPI
    ``bpy``) keeps its Python packages out of ``sys.path``."""
    try:
        import pxr  # noqa: F401
    except ImportError:
        version = "python%d.%d" % sys.version_info[:2]
        site = os.path.join(bpy.utils.system_resource("PYTHON"), "lib", version, "site-packages")
        if site not in sys.path:
            sys.path.append(site)


def _clothsr():
    _blender_usd()
    import clothsr

    return clothsr


class ClothsrSettings(bpy.types.PropertyGroup):
    source: EnumProperty(
        name="Source",
        items=[
            ("FILE", "USD shot", "A USD shot file: its garments and colliders as the file marks them"),
            ("SCENE", "This scene", "The current scene exported to USD: one garment object, the other meshes collide"),
        ],
        default="FILE",
    )
    shot: StringProperty(name="Shot", subtype="FILE_PATH", description="The USD shot to run")
    garment: PointerProperty(
        name="Garment",
        type=bpy.types.Object,
        poll=lambda self, obj: obj.type == "MESH",
        description="The garment mesh (about 20 mm edges); every other mesh is a collider",
    )
    fabric: EnumProperty(name="Fabric", items=FABRICS, default="cotton", description="For garments without a fabric")
    output: StringProperty(
        name="Output folder",
        subtype="DIR_PATH",
        default="//clothsr",
        description="Where the fine cloth goes (blank: a temporary folder)",
    )
    models: StringProperty(
        name="Models", subtype="DIR_PATH", description="A models folder (blank: the generic models)"
    )
    frames: IntProperty(name="Frames", min=0, default=0, description="Frames to run (0: the shot's range)")
    restart: BoolProperty(name="Restart", description="Start over instead of resuming an interrupted run")


def _output_dir(settings) -> pathlib.Path:
    path = bpy.path.abspath(settings.output) if settings.output else ""
    if not path or (path.startswith("//") or not os.path.isabs(path)):
        path = os.path.join(tempfile.gettempdir(), "clothsr")
    out = pathlib.Path(path)
    out.mkdir(parents=True, exist_ok=True)
    return out


def _export_scene(context, settings, folder: pathlib.Path):
    """The current scene as a USD shot clothsr reads: the garment object's mesh marked as cloth
    (``ClothsrGarmentAPI``, its fabric), every other mesh as a collider
    (``PhysicsCollisionAPI``). Returns (shot path, the garment's prim path)."""
    garment = settings.garment
    if garment is None or garment.type != "MESH":
        raise ValueError("choose the garment object (a mesh) in the clothsr panel")
    name = bpy.path.clean_name(pathlib.Path(bpy.data.filepath).stem or "scene")
    shot = folder / f"{name}_shot.usdc"
    result = bpy.ops.wm.usd_export(
        filepath=str(shot),
        export_animation=True,
        export_materials=False,
        export_lights=False,
        export_cameras=False,
        check_existing=False,
    )
    if "FINISHED" not in result:
        raise RuntimeError(f"Blender's USD export to {shot} returned {result}")
    _blender_usd()
    from pxr import Sdf, Usd, UsdGeom

    stage = Usd.Stage.Open(str(shot))
    target = None
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        owner = prim.GetParent().GetAttribute("userProperties:blender:object_name")
        if owner and owner.Get() == garment.name and target is None:
            prim.AddAppliedSchema("ClothsrGarmentAPI")
            prim.CreateAttribute("clothsr:fabric:name", Sdf.ValueTypeNames.String).Set(settings.fabric)
            target = str(prim.GetPath())
        else:
            prim.AddAppliedSchema("PhysicsCollisionAPI")
    if target is None:
        raise ValueError(f"{garment.name}: not in the exported scene (is it visible?)")
    stage.GetRootLayer().Save()
    return shot, target


class _Run:
    """One clothsr run: the shot, where it goes, and what the background thread reports."""

    def __init__(self, context):
        settings = context.scene.clothsr
        self.settings = settings
        folder = _output_dir(settings)
        if settings.source == "SCENE":
            self.shot, self.mask = _export_scene(context, settings, folder)
            self.hide = settings.garment
        else:
            if not settings.shot:
                raise ValueError("choose a USD shot in the clothsr panel")
            self.shot = pathlib.Path(bpy.path.abspath(settings.shot))
            if not self.shot.is_file():
                raise ValueError(f"{self.shot}: no such file")
            self.mask = ""
            self.hide = None
        self.output = folder / f"{self.shot.stem}_cloth.usdc"
        self.models = bpy.path.abspath(settings.models) if settings.models else None
        self.done, self.total = 0, 0
        self.cancel = False
        self.error = None

    def progress(self, done: int, total: int):
        self.done, self.total = done, total
        return not self.cancel

    def run(self):
        """Runs clothsr (any thread); a failure is kept in ``error``."""
        clothsr = _clothsr()
        try:
            clothsr.run(
                str(self.shot),
                str(self.output),
                models=self.models,
                frames=self.settings.frames or None,
                fabric=self.settings.fabric,
                restart=self.settings.restart,
                layer=True,
                progress=self.progress,
            )
        except clothsr.Cancelled:
            self.error = "cancelled: run again to resume"
        except clothsr.ClothsrError as exc:
            self.error = str(exc)

    def bring_in(self, context):
        """Imports the shot composed with the fine cloth (only the garment when the shot is
        this scene), with the shot's frame range."""
        import clothsr_usd

        composed = clothsr_usd.composed_path(self.output)
        result = bpy.ops.wm.usd_import(filepath=str(composed), set_frame_range=True, prim_path_mask=self.mask)
        if "FINISHED" not in result:
            raise RuntimeError(f"Blender's USD import of {composed} returned {result}")
        if self.hide is not None:
            self.hide.hide_set(True)
            self.hide.hide_render = True
        return composed


class CLOTHSR_OT_run(bpy.types.Operator):
    """Run clothsr on the shot and import the fine cloth"""

    bl_idname = "clothsr.run"
    bl_label = "Run clothsr"
    bl_options = {"REGISTER"}

    _timer = None
    _thread = None
    _job = None
    running = None  # the job of the run in progress, for the Cancel button

    def _start(self, context):
        try:
            return _Run(context)
        except (ValueError, RuntimeError, OSError) as exc:
            self.report({"ERROR"}, str(exc))
            return None

    def _finish(self, context, job):
        if job.error:
            self.report({"ERROR"} if "cancelled" not in job.error else {"WARNING"}, f"clothsr: {job.error}")
            return {"CANCELLED"}
        try:
            composed = job.bring_in(context)
        except RuntimeError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, f"clothsr: {composed.name} imported")
        return {"FINISHED"}

    def execute(self, context):
        """Runs to the end in this call (scripts, headless Blender)."""
        job = self._start(context)
        if job is None:
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, 1)
        job.progress = lambda done, total: wm.progress_update(done / max(total, 1)) or True
        try:
            job.run()
        finally:
            wm.progress_end()
        return self._finish(context, job)

    def invoke(self, context, event):
        """Runs in a background thread, with progress in the status bar; Esc stops it."""
        if CLOTHSR_OT_run.running is not None:
            self.report({"WARNING"}, "clothsr is already running")
            return {"CANCELLED"}
        job = self._start(context)
        if job is None:
            return {"CANCELLED"}
        self._job = job
        CLOTHSR_OT_run.running = job
        self._thread = threading.Thread(target=job.run, name="clothsr", daemon=True)
        self._thread.start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.25, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC":
            job.cancel = True
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if self._thread.is_alive():
            what = f"{job.done}/{job.total} frames" if job.total else "setting up"
            context.workspace.status_text_set(f"clothsr: {what} (Esc to stop)")
            return {"RUNNING_MODAL"}
        context.window_manager.event_timer_remove(self._timer)
        context.workspace.status_text_set(None)
        CLOTHSR_OT_run.running = None
        return self._finish(context, job)


class CLOTHSR_OT_cancel(bpy.types.Operator):
    """Stop the clothsr run in progress (it resumes when run again)"""

    bl_idname = "clothsr.cancel"
    bl_label = "Cancel"

    @classmethod
    def poll(cls, context):
        return CLOTHSR_OT_run.running is not None

    def execute(self, context):
        CLOTHSR_OT_run.running.cancel = True
        return {"FINISHED"}


class CLOTHSR_PT_panel(bpy.types.Panel):
    bl_label = "clothsr"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "clothsr"

    def draw(self, context):
        settings = context.scene.clothsr
        layout = self.layout
        layout.prop(settings, "source", expand=True)
        if settings.source == "FILE":
            layout.prop(settings, "shot")
        else:
            layout.prop(settings, "garment")
        layout.prop(settings, "fabric")
        layout.prop(settings, "frames")
        layout.prop(settings, "output")
        layout.prop(settings, "models")
        layout.prop(settings, "restart")
        job = CLOTHSR_OT_run.running
        if job is None:
            layout.operator(CLOTHSR_OT_run.bl_idname, icon="MOD_CLOTH")
        else:
            row = layout.row()
            row.label(text=f"{job.done}/{job.total} frames" if job.total else "setting up")
            row.operator(CLOTHSR_OT_cancel.bl_idname, icon="CANCEL")


CLASSES = (ClothsrSettings, CLOTHSR_OT_run, CLOTHSR_OT_cancel, CLOTHSR_PT_panel)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.clothsr = PointerProperty(type=ClothsrSettings)


def unregister():
    del bpy.types.Scene.clothsr
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
