"""Run inside Blender by tests/test_blender.py: ``blender -b --factory-startup --python-exit-code 1
-P tests/blender_check.py -- CONFIG.json``.

Installs and enables the add-on from lipsync's zip, runs its operators as the config says,
renders the chosen frames (Workbench, flat texture colour, orthographic camera filling the
frame exactly) and writes what Blender shows -- the renders, the keyed values, the sound strip --
to the config's ``out`` folder and ``results.json``. The comparisons with lipsync's own frames
and cues are made by the test, outside Blender.
"""

import json
import math
import sys

import bpy

cfg = json.load(open(sys.argv[sys.argv.index("--") + 1]))
out = cfg["out"]
results = {"renders": {}, "values": {}}

bpy.ops.preferences.addon_install(filepath=cfg["zip"])
bpy.ops.preferences.addon_enable(module="lipsync_blender")
import lipsync_blender  # noqa: E402  (installed just now)

results["module_file"] = lipsync_blender.__file__
import importlib.util  # noqa: E402

results["lipsync_importable"] = importlib.util.find_spec("lipsync") is not None  # the add-on must not need it
scene = bpy.context.scene
for obj in list(scene.objects):  # the factory cube, light and camera
    bpy.data.objects.remove(obj)
scene.frame_start = cfg["frame_start"]
scene.frame_end = cfg["frame_start"] + 200
scene.render.engine = "BLENDER_WORKBENCH"
scene.display.shading.light = "FLAT"
scene.display.shading.color_type = "TEXTURE"
scene.display.render_aa = "OFF"
scene.view_settings.view_transform = "Standard"
scene.render.film_transparent = True
scene.render.dither_intensity = 0.0  # no noise added to the renders compared
scene.render.image_settings.file_format = "PNG"
scene.render.image_settings.color_mode = "RGBA"

cam_data = bpy.data.cameras.new("cam")
cam_data.type = "ORTHO"
cam = bpy.data.objects.new("cam", cam_data)
scene.collection.objects.link(cam)
cam.location = (0.0, -5.0, 0.0)
cam.rotation_euler = (math.pi / 2, 0.0, 0.0)  # looking along +Y at the plane's front
scene.camera = cam


def emit(obj):
    """Eevee renders lit colours; for a pixel comparison the picture is emitted instead (the
    colour and alpha the add-on connected to the Principled BSDF, unchanged)."""
    nt = obj.active_material.node_tree
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
    color = bsdf.inputs["Base Color"].links[0].from_socket
    alpha = bsdf.inputs["Alpha"].links[0].from_socket
    emission, clear, mix = (nt.nodes.new(k) for k in ("ShaderNodeEmission", "ShaderNodeBsdfTransparent",
                                                       "ShaderNodeMixShader"))
    nt.links.new(color, emission.inputs["Color"])
    nt.links.new(alpha, mix.inputs["Fac"])
    nt.links.new(clear.outputs[0], mix.inputs[1])
    nt.links.new(emission.outputs[0], mix.inputs[2])
    output = next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")
    nt.links.new(mix.outputs[0], output.inputs["Surface"])


def render(name, frame, size):
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    cam_data.ortho_scale = max(size) / min(size) if size[0] != size[1] else 1.0  # plane height 1
    scene.frame_set(frame)
    path = f"{out}/{name}_{frame}.png"
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    results["renders"].setdefault(name, {})[str(frame)] = path


for case in cfg["cases"]:
    scene.render.fps, scene.render.fps_base = case.get("scene_fps", 24), 1.0
    for obj in scene.objects:
        if obj.type == "MESH":
            obj.hide_render = True  # earlier cases' planes
    kind = case["kind"]
    if kind == "bad":  # an operator given a bad file: it must refuse with a message, change nothing
        before = len(bpy.data.objects), len(bpy.data.images)
        op = getattr(bpy.ops.lipsync, case["operator"])
        try:
            r, message = op(filepath=case["path"], **case.get("options", {})), None
        except RuntimeError as exc:  # background mode raises an operator's ERROR report
            r, message = {"CANCELLED"}, str(exc)
        results["values"][case["name"]] = {"result": sorted(r), "message": message,
                                           "unchanged": before == (len(bpy.data.objects), len(bpy.data.images))}
        continue
    if kind == "import":
        target = case.get("target", "PLANE")
        if target == "MATERIAL":  # the user's own object, material and image node
            mesh = bpy.data.meshes.new("face")
            mesh.from_pydata([(-0.6, 0, -0.5), (0.6, 0, -0.5), (0.6, 0, 0.5), (-0.6, 0, 0.5)], [], [(0, 1, 2, 3)])
            uv = mesh.uv_layers.new(name="UVMap")
            for loop, co in zip(uv.data, ((0, 0), (1, 0), (1, 1), (0, 1))):
                loop.uv = co
            face = bpy.data.objects.new("face", mesh)
            scene.collection.objects.link(face)
            mat = bpy.data.materials.new("skin")
            mat.use_nodes = True
            mat.node_tree.nodes.new("ShaderNodeTexImage")
            face.data.materials.append(mat)
            bpy.context.view_layer.objects.active = face
        r = bpy.ops.lipsync.import_render(filepath=case["path"], fps=case.get("fps", 25.0), sound=case.get("sound", ""),
                                          target=target)
        assert r == {"FINISHED"}, r
        plane = bpy.context.active_object
        scene.render.engine = case.get("engine", "BLENDER_WORKBENCH")
        if scene.render.engine == "BLENDER_EEVEE":
            emit(plane)
            scene.eevee.taa_render_samples = 1
            scene.render.filter_size = 0.0
        editor = scene.sequence_editor
        sounds = [{"name": s.name, "frame_final_start": s.frame_final_start,
                   "frame_final_duration": s.frame_final_duration, "filepath": bpy.path.abspath(s.sound.filepath)}
                  for s in (editor.sequences_all if editor else []) if s.type == "SOUND"]
        results["values"][case["name"]] = {"object": plane.name, "dimensions": list(plane.dimensions),
                                           "sounds": sounds}
        for f in case["frames"]:
            render(case["name"], f, case["size"])
    elif kind == "cues":
        obj = bpy.data.objects.new(case["name"], bpy.data.meshes.new(case["name"]))
        scene.collection.objects.link(obj)
        if case["target"] == "SHAPE_KEYS":
            obj.data.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [(0, 1, 2)])
            obj.shape_key_add(name="Basis")
            for s in case["keys"]:
                obj.shape_key_add(name=case.get("prefix", "") + s)
        elif case["target"] == "POSE":
            arm = bpy.data.armatures.new(case["name"])
            obj = bpy.data.objects.new(case["name"] + "_rig", arm)
            scene.collection.objects.link(obj)
            bpy.context.view_layer.objects.active = obj
            bpy.ops.object.mode_set(mode="EDIT")
            bone = arm.edit_bones.new("jaw")
            bone.head, bone.tail = (0, 0, 0), (0, 0, 1)
            bpy.ops.object.mode_set(mode="OBJECT")
            for i, s in enumerate(case["keys"]):  # pose action i: jaw moved by i along z
                act = bpy.data.actions.new(case.get("prefix", "") + s)
                act.use_fake_user = True
                fc = act.fcurves.new('pose.bones["jaw"].location', index=2, action_group="jaw")
                fc.keyframe_points.insert(1.0, float(i))
        bpy.context.view_layer.objects.active = obj
        for o in scene.objects:
            o.select_set(o is obj)
        r = bpy.ops.lipsync.key_cues(filepath=case["path"], target=case["target"], prefix=case.get("prefix", ""),
                                     property_name=case.get("property", "lipsync_shape"))
        assert r == {"FINISHED"}, r
        values = {}
        for f in case["frames"]:
            scene.frame_set(f)
            if case["target"] == "PROPERTY":
                values[str(f)] = obj[case.get("property", "lipsync_shape")]
            elif case["target"] == "SHAPE_KEYS":
                values[str(f)] = {k.name: k.value for k in obj.data.shape_keys.key_blocks[1:]}
            else:
                values[str(f)] = obj.pose.bones["jaw"].location[2]
        results["values"][case["name"]] = values

registered = hasattr(bpy.types, "LIPSYNC_OT_import_render")
bpy.ops.preferences.addon_disable(module="lipsync_blender")
results["unregistered"] = registered and not hasattr(bpy.types, "LIPSYNC_OT_import_render")
json.dump(results, open(f"{out}/results.json", "w"), indent=1)
