"""lipsync for Blender: import a lipsync render onto a plane or a material, key mouth cues.

Runs on Blender's own Python with nothing of lipsync installed: it only reads the files
lipsync wrote (a PNG sequence, an atlas + frames.json, mouth cues). The frame rule is in
``files.py``: Blender frame ``f`` shows lipsync frame ``floor((f - start) * fps / scene_fps)``.

Operators (3D View > Sidebar > lipsync, and File > Import):

* ``lipsync.import_render``: a PNG sequence (``lipsync render ... -o FOLDER/``) or an atlas's
  ``frames.json`` onto a new plane or the active object's material, lined up with the scene's
  frames, and the speech as a sound strip at the same start;
* ``lipsync.key_cues``: mouth cues (Rhubarb TSV/JSON/XML, TextGrid, Audacity, Moho) keyed on
  an integer custom property, on shape keys, or as poses (actions / pose assets) of an armature.
"""

bl_info = {
    "name": "lipsync",
    "author": "lipsync contributors",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "3D View > Sidebar > lipsync; File > Import > lipsync render",
    "description": "Import lipsync renders (PNG sequences, sprite atlases) lined up with the scene's "
                   "frames, with the speech; key mouth cues onto a property, shape keys or poses",
    "category": "Animation",
}

if "bpy" in locals():  # Blender's "Reload Scripts"
    import importlib

    importlib.reload(files)  # noqa: F821
    importlib.reload(build)  # noqa: F821
else:
    from . import build, files

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper


def _start(scene, use_scene_start, frame_start):
    return scene.frame_start if use_scene_start else frame_start


class LIPSYNC_OT_import_render(bpy.types.Operator, ImportHelper):
    """Import a lipsync render (a frame of a PNG sequence, or a frames.json) lined up with the scene"""

    bl_idname = "lipsync.import_render"
    bl_label = "Import lipsync render"
    bl_options = {"REGISTER", "UNDO"}

    filter_glob: StringProperty(default="*.png;*.json", options={"HIDDEN"})
    fps: FloatProperty(name="Render fps", default=25.0, min=1.0, max=1000.0,
                       description="The --fps the PNG frames were rendered at (lipsync's default is 25); "
                                   "a frames.json carries its own")
    sound: StringProperty(name="Speech", subtype="FILE_PATH", default="",
                          description="The speech, added as a sound strip at the same start (optional)")
    target: EnumProperty(name="Onto", default="PLANE", items=[
        ("PLANE", "New plane", "A new plane with the frame's aspect and its own material"),
        ("MATERIAL", "Active material", "The active object's active material: its active Image Texture "
                                        "node (PNG frames), or its Principled BSDF (atlas)"),
    ])
    use_scene_start: BoolProperty(name="At the scene's start", default=True,
                                  description="Start at the scene's first frame, else at Start frame")
    frame_start: IntProperty(name="Start frame", default=1, description="The Blender frame of lipsync frame 0")
    height: FloatProperty(name="Plane height", default=1.0, min=1e-4, unit="LENGTH")

    def execute(self, context):
        scene = context.scene
        start = _start(scene, self.use_scene_start, self.frame_start)
        try:
            if self.sound:  # checked first: a refusal leaves nothing half-made
                build.check_sound(bpy.path.abspath(self.sound))
            if self.filepath.lower().endswith(".json"):
                clip = files.atlas_clip(self.filepath)
                made = build.import_atlas(context, clip, start=start, target=self.target, height=self.height)
                count, fps = len(clip.frames), clip.fps
            else:
                seq = files.png_sequence(self.filepath)
                made = build.import_sequence(context, seq, start=start, fps=self.fps, target=self.target,
                                             height=self.height)
                count, fps = len(seq.numbers), self.fps
            strip = build.add_sound(scene, bpy.path.abspath(self.sound), start=start) if self.sound else None
        except (files.LipsyncFileError, build.TargetError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if strip is not None:
            # lipsync renders ceil(duration * fps) frames: a clip much longer or shorter than its
            # speech was rendered at another rate than the one given
            speech = strip.frame_final_duration / build.scene_fps(scene)
            if abs(count / fps - speech) > 1.5 / fps + 1.0 / build.scene_fps(scene):  # + the strip's rounding
                self.report({"WARNING"}, f"lipsync: {count} frames at {fps:g} fps last {count / fps:.2f} s but the "
                                         f"speech lasts {speech:.2f} s: is Render fps the --fps they were rendered at?")
        last = start + (count / fps) * build.scene_fps(scene)
        self.report({"INFO"}, f"lipsync: {count} frames at {fps:g} fps on {made.name}, Blender frames "
                              f"{start} to {last:.1f}")
        return {"FINISHED"}


class LIPSYNC_OT_key_cues(bpy.types.Operator, ImportHelper):
    """Key mouth cues onto the active object: an integer property, shape keys, or poses"""

    bl_idname = "lipsync.key_cues"
    bl_label = "Key lipsync cues"
    bl_options = {"REGISTER", "UNDO"}

    filter_glob: StringProperty(default="*.tsv;*.json;*.xml;*.TextGrid;*.txt;*.dat", options={"HIDDEN"})
    target: EnumProperty(name="Onto", default="PROPERTY", items=[
        ("PROPERTY", "Integer property", "An integer custom property of the object (drive anything with it): "
                                         "the shape's place in Shapes"),
        ("SHAPE_KEYS", "Shape keys", "Shape keys named Prefix + shape: 1 on the cue's, 0 on the others"),
        ("POSE", "Poses (actions)", "An armature: the pose stored in the action (or pose asset) named "
                                    "Prefix + shape, for every cue"),
    ])
    property_name: StringProperty(name="Property", default="lipsync_shape")
    shapes: StringProperty(name="Shapes", default=files.RHUBARB_SHAPES,
                           description="The order of the property's values: letters, or names separated by "
                                       "commas; shapes not listed are appended")
    prefix: StringProperty(name="Prefix", default="", description="Shape key / action name = Prefix + shape")
    use_scene_start: BoolProperty(name="At the scene's start", default=True)
    frame_start: IntProperty(name="Start frame", default=1, description="The Blender frame of time 0")
    moho_fps: FloatProperty(name="Moho fps", default=24.0, min=1.0, description="Frame rate of a .dat file")

    def execute(self, context):
        obj = context.active_object
        start = _start(context.scene, self.use_scene_start, self.frame_start)
        try:
            if obj is None:
                raise build.TargetError("select the object to key first")
            cues = files.read_cues(self.filepath, moho_fps=self.moho_fps)
            if self.target == "PROPERTY":
                note = build.key_property(context.scene, obj, cues, start=start, name=self.property_name,
                                          order=build.shape_order(self.shapes))
            elif self.target == "SHAPE_KEYS":
                note = build.key_shape_keys(context.scene, obj, cues, start=start, prefix=self.prefix)
            else:
                note = build.key_poses(context.scene, obj, cues, start=start, prefix=self.prefix)
        except (files.LipsyncFileError, build.TargetError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, f"lipsync: {len(cues.starts)} cues keyed on {obj.name}{note}")
        return {"FINISHED"}


class LIPSYNC_PT_panel(bpy.types.Panel):
    bl_label = "lipsync"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "lipsync"

    def draw(self, context):
        col = self.layout.column(align=True)
        col.operator(LIPSYNC_OT_import_render.bl_idname, icon="IMAGE_DATA")
        col.operator(LIPSYNC_OT_key_cues.bl_idname, icon="SHAPEKEY_DATA")


def _menu_import(self, context):
    self.layout.operator(LIPSYNC_OT_import_render.bl_idname, text="lipsync render (PNG frames, atlas)")
    self.layout.operator(LIPSYNC_OT_key_cues.bl_idname, text="lipsync / Rhubarb mouth cues")


_CLASSES = (LIPSYNC_OT_import_render, LIPSYNC_OT_key_cues, LIPSYNC_PT_panel)


def register():
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(_menu_import)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(_menu_import)
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
