"""The Blender side: planes, materials, constant keys, sound strips (the rule is in files.py)."""

import os

import bpy

from . import files


class TargetError(ValueError):
    """The object or material to work on is missing or of the wrong kind; the message says which."""


def scene_fps(scene) -> float:
    return scene.render.fps / scene.render.fps_base


# ---- keys -----------------------------------------------------------------------------------

def _action(id_data, name):
    anim = id_data.animation_data or id_data.animation_data_create()
    if anim.action is None:
        anim.action = bpy.data.actions.new(name)
    return anim.action


def constant_keys(id_data, data_path, index, points, *, name, group=None):
    """Replace the fcurve ``data_path[index]`` of ``id_data`` by constant keys at ``points``.

    ``points``: ``(frame, value)``; a run of equal values keeps only its first key.
    """
    action = _action(id_data, name)
    old = action.fcurves.find(data_path, index=index)
    if old is not None:
        action.fcurves.remove(old)
    fc = action.fcurves.new(data_path, index=index, action_group=group or "")
    kept = []
    for frame, value in points:
        if not kept or kept[-1][1] != value:
            kept.append((frame, value))
    fc.keyframe_points.add(len(kept))
    fc.keyframe_points.foreach_set("co", [c for pt in kept for c in pt])
    for kp in fc.keyframe_points:
        kp.interpolation = "CONSTANT"
    fc.update()
    return fc


# ---- the picture: a plane, or the user's material ---------------------------------------------

def _plane(context, name, aspect, height):
    w, h = height * aspect, height
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([(-w / 2, 0, -h / 2), (w / 2, 0, -h / 2), (w / 2, 0, h / 2), (-w / 2, 0, h / 2)], [],
                     [(0, 1, 2, 3)])
    uv = mesh.uv_layers.new(name="UVMap")
    for loop, co in zip(uv.data, ((0, 0), (1, 0), (1, 1), (0, 1))):
        loop.uv = co
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)  # upright, facing -Y: the front view sees it
    context.collection.objects.link(obj)
    for o in context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    context.view_layer.objects.active = obj
    return obj


def _new_material(obj, name):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    # Alpha blending in Eevee (the mouth's transparent pixels); `blend_method` until Blender 4.2
    if hasattr(mat, "blend_method"):
        mat.blend_method = "BLEND"
    if hasattr(mat, "shadow_method"):
        mat.shadow_method = "CLIP"
    obj.data.materials.append(mat)
    return mat


def _bsdf(mat):
    bsdf = next((n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None)
    if bsdf is None:
        raise TargetError(f"material {mat.name} has no Principled BSDF to connect the picture to")
    return bsdf


def _active_material(context):
    obj = context.active_object
    mat = obj.active_material if obj is not None else None
    if mat is None or not mat.use_nodes:
        raise TargetError("the active object has no node material: select the object whose material "
                          "should show the render, or import onto a new plane")
    return obj, mat


def _load_image(path, *, sequence=False):
    img = bpy.data.images.load(path, check_existing=False)
    img.alpha_mode = "STRAIGHT"  # lipsync writes straight alpha
    if sequence:
        img.source = "SEQUENCE"
    return img


def import_sequence(context, seq, *, start, fps, target, height):
    """A PNG sequence on a plane or the active material's image node; returns the object."""
    scene = context.scene
    first = os.path.join(seq.folder, seq.files[0])
    if target != "PLANE":  # the user's node first: a refusal must leave nothing behind
        obj, mat = _active_material(context)
        nodes = mat.node_tree.nodes
        tex = nodes.active if nodes.active is not None and nodes.active.type == "TEX_IMAGE" else \
            next((n for n in nodes if n.type == "TEX_IMAGE"), None)
        if tex is None:
            raise TargetError(f"material {mat.name} has no Image Texture node to show the frames")
    img = _load_image(first, sequence=True)
    w, h = img.size
    if target == "PLANE":
        obj = _plane(context, "lipsync", w / max(h, 1), height)
        mat = _new_material(obj, "lipsync")
        tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
        tex.location = (-400, 300)
        bsdf = _bsdf(mat)
        mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
        mat.node_tree.links.new(tex.outputs["Alpha"], bsdf.inputs["Alpha"])
    tex.image = img
    mat.node_tree.nodes.active = tex  # what Workbench's Texture colour and the viewport show
    user = tex.image_user
    user.use_auto_refresh = True
    user.frame_start = start
    count = len(seq.numbers)
    if abs(fps - scene_fps(scene)) < 1e-6:
        # Same rate: Blender's own sequence mapping. Frame f shows file number
        # (f - start + 1) + offset, so offset = first number - 1 (frame_000000.png at `start`).
        user.use_cyclic = False
        user.frame_duration = count
        user.frame_offset = seq.numbers[0] - 1
        anim = mat.node_tree.animation_data
        if anim is not None and anim.action is not None:
            old = anim.action.fcurves.find(user.path_from_id("frame_offset"))
            if old is not None:
                anim.action.fcurves.remove(old)
    else:
        # Other rates, by time: a one-frame cyclic "sequence" always shows file 1 + offset,
        # and the offset is keyed to number - 1 where each lipsync frame begins.
        user.use_cyclic = True
        user.frame_duration = 1
        sfps = scene_fps(scene)
        constant_keys(mat.node_tree, user.path_from_id("frame_offset"), 0,
                      [(files.key_frame(k / fps, frame_start=start, scene_fps=sfps), n - 1)
                       for k, n in enumerate(seq.numbers)], name=f"{mat.name} lipsync", group="lipsync")
    return obj


def _node(nt, kind, location, **settings):
    node = nt.nodes.new(kind)
    node.location = location
    for key, value in settings.items():
        setattr(node, key, value)
    return node


def _math(nt, op, a, b, location):
    node = _node(nt, "ShaderNodeMath", location, operation=op)
    for i, x in enumerate((a, b)):
        if isinstance(x, (int, float)):
            node.inputs[i].default_value = x
        else:
            nt.links.new(x, node.inputs[i])
    return node.outputs[0]


def import_atlas(context, clip, *, start, target, height):
    """An atlas + frames.json: the base image and the keyed cell in one material; returns the object.

    The cell is drawn into the region by a Mapping node whose Location is keyed per frame (the
    cell's corner in the texture), masked to the region; outside it the base shows.
    """
    scene = context.scene
    atlas = clip.atlas
    W, H = atlas["frame_size"]
    IW, IH = atlas["image_size"]
    rx, ry, rw, rh = atlas["region"]
    scale = float(atlas.get("scale", 1.0))
    if target == "PLANE":
        obj = _plane(context, "lipsync", W / H, height)
        mat = _new_material(obj, "lipsync atlas")
    else:
        obj, mat = _active_material(context)
    _bsdf(mat)  # refuse a material without one before adding anything
    nt = mat.node_tree
    uv = _node(nt, "ShaderNodeTexCoord", (-1400, 300)).outputs["UV"]
    # texture UV = corner(cell) + frame UV * (frame size * scale / texture size); v grows up
    mapping = _node(nt, "ShaderNodeMapping", (-1150, 300), vector_type="POINT")
    nt.links.new(uv, mapping.inputs["Vector"])
    mapping.inputs["Scale"].default_value = (W * scale / IW, H * scale / IH, 1.0)
    cells = atlas["cells"]

    def corner(i):
        x, y = cells[i]["rect"][:2]
        return ((x - rx * scale) / IW, 1.0 - (y + (H - ry) * scale) / IH)

    sfps = scene_fps(scene)
    keys = [(files.key_frame(k / clip.fps, frame_start=start, scene_fps=sfps), corner(c))
            for k, c in enumerate(clip.frames)]
    path = mapping.inputs["Location"].path_from_id("default_value")
    for axis in (0, 1):
        constant_keys(nt, path, axis, [(f, xy[axis]) for f, xy in keys], name=f"{mat.name} lipsync",
                      group="lipsync")
    mapping.inputs["Location"].default_value[:2] = keys[0][1]
    cell = _node(nt, "ShaderNodeTexImage", (-900, 300), image=_load_image(
        os.path.join(clip.folder, atlas["image"])), extension="EXTEND", interpolation="Closest")
    nt.links.new(mapping.outputs["Vector"], cell.inputs["Vector"])
    # The region as a 0/1 mask in frame UV (v grows up: the region's top row is v = 1 - ry / H).
    # Both textures are sampled Closest: the base's last opaque texel then ends exactly where
    # the mask begins, at any zoom. (Linear filtering with the GPU's mipmaps, as Eevee samples
    # it, fades the base's alpha over part of the neighbouring texel: a visible seam.)
    sep = _node(nt, "ShaderNodeSeparateXYZ", (-1150, -100))
    nt.links.new(uv, sep.inputs[0])
    u, v = sep.outputs[0], sep.outputs[1]
    sides = [("GREATER_THAN", u, rx / W), ("LESS_THAN", u, (rx + rw) / W),
             ("LESS_THAN", v, 1.0 - ry / H), ("GREATER_THAN", v, 1.0 - (ry + rh) / H)]
    steps = [_math(nt, op, coord, edge, (-900, -50 - 150 * i)) for i, (op, coord, edge) in enumerate(sides)]
    inside = _math(nt, "MULTIPLY", _math(nt, "MULTIPLY", steps[0], steps[1], (-700, -100)),
                   _math(nt, "MULTIPLY", steps[2], steps[3], (-700, -400)), (-500, -250))
    alpha = _math(nt, "MULTIPLY", cell.outputs["Alpha"], inside, (-250, -100))
    color = cell.outputs["Color"]
    if atlas.get("base"):
        base = _node(nt, "ShaderNodeTexImage", (-900, 650), image=_load_image(
            os.path.join(clip.folder, atlas["base"])), interpolation="Closest")
        nt.links.new(uv, base.inputs["Vector"])
        mix = _node(nt, "ShaderNodeMixRGB", (-250, 400), blend_type="MIX")
        nt.links.new(inside, mix.inputs["Fac"])
        nt.links.new(base.outputs["Color"], mix.inputs["Color1"])
        nt.links.new(cell.outputs["Color"], mix.inputs["Color2"])
        color = mix.outputs["Color"]
        # the base is clear inside the region, the cell is masked outside it: the alpha is the sum
        total = _math(nt, "ADD", alpha, base.outputs["Alpha"], (-100, -200))
        total.node.use_clamp = True
        alpha = total
    bsdf = _bsdf(mat)
    nt.links.new(color, bsdf.inputs["Base Color"])
    nt.links.new(alpha, bsdf.inputs["Alpha"])
    nt.nodes.active = cell
    return obj


def check_sound(path):
    if not os.path.isfile(path):
        raise files.LipsyncFileError(f"{path}: no such sound file")


def add_sound(scene, path, *, start):
    """The speech as a sound strip starting at Blender frame ``start`` (the first free channel)."""
    check_sound(path)
    editor = scene.sequence_editor or scene.sequence_editor_create()
    # Blender 4.4 renamed the sequencer's `sequences` to `strips`
    every = getattr(editor, "strips_all", None) or editor.sequences_all
    channel = 1 + max((s.channel for s in every), default=0)
    strips = getattr(editor, "strips", None) or editor.sequences
    return strips.new_sound(os.path.basename(path), path, channel, start)


# ---- cues -------------------------------------------------------------------------------------

def shape_order(text):
    """'ABCDEFGHX' -> letters; 'rest, MBP, AI' -> names."""
    if "," in text or " " in text.strip():
        return [s.strip() for s in text.replace(",", " ").split() if s.strip()]
    return list(text.strip())


def _cue_points(scene, cues, start):
    sfps = scene_fps(scene)
    return [(files.key_frame(s, frame_start=start, scene_fps=sfps), shape) for s, shape in cues.starts]


def key_property(scene, obj, cues, *, start, name, order):
    """An integer custom property: the index of each cue's shape in ``order``."""
    order = list(order)
    added = []
    for _, s in cues.starts:
        if s not in order:
            order.append(s)
            added.append(s)
    obj[name] = order.index(cues.starts[0][1])
    ui = obj.id_properties_ui(name)
    ui.update(min=0, max=max(len(order) - 1, 0), description=f"lipsync mouth shape: {' '.join(order)}")
    obj[name + "_shapes"] = " ".join(order)  # what each value means, for drivers and people
    constant_keys(obj, f'["{name}"]', 0, [(f, order.index(s)) for f, s in _cue_points(scene, cues, start)],
                  name=f"{obj.name} lipsync", group="lipsync")
    return f" ({name}; shapes not in the list appended: {' '.join(added)})" if added else f" ({name})"


def key_shape_keys(scene, obj, cues, *, start, prefix):
    """Shape keys ``prefix + shape``: 1 on the cue's key, 0 on the others, constant."""
    keys = obj.data.shape_keys if getattr(obj, "data", None) is not None and hasattr(obj.data, "shape_keys") \
        else None
    if keys is None:
        raise TargetError(f"{obj.name} has no shape keys")
    shapes = list(dict.fromkeys(s for _, s in cues.starts))
    blocks = {s: keys.key_blocks.get(prefix + s) for s in shapes}
    found = [s for s in shapes if blocks[s] is not None and blocks[s] != keys.reference_key]
    if not found:
        raise TargetError(f"{obj.name} has none of the shape keys {', '.join(prefix + s for s in shapes)}")
    points = _cue_points(scene, cues, start)
    for s in found:
        block = blocks[s]
        constant_keys(keys, block.path_from_id("value"), 0, [(f, 1.0 if c == s else 0.0) for f, c in points],
                      name=f"{obj.name} lipsync", group="lipsync")
    missing = [s for s in shapes if s not in found]
    return f" (no shape key for {', '.join(missing)}: the basis shows there)" if missing else ""


def _rest_value(data_path, index):
    # what a channel a pose does not set returns to: the bone's rest transform
    if data_path.endswith("rotation_quaternion"):
        return (1.0, 0.0, 0.0, 0.0)[index]
    if data_path.endswith("rotation_axis_angle"):  # angle, then the axis: Blender's default is Y
        return (0.0, 0.0, 1.0, 0.0)[index]
    if data_path.endswith("scale"):
        return 1.0
    return 0.0


def key_poses(scene, obj, cues, *, start, prefix):
    """An armature: for every cue, the pose held by the action (or pose asset) ``prefix + shape``.

    Each pose action's value at its first frame is keyed, constant; a channel a pose does not
    set is keyed at its rest value, so one shape's jaw does not linger into the next.
    """
    if obj.type != "ARMATURE":
        raise TargetError(f"{obj.name} is not an armature (poses are keyed on an armature)")
    shapes = list(dict.fromkeys(s for _, s in cues.starts))
    poses = {s: bpy.data.actions.get(prefix + s) for s in shapes}
    missing = [prefix + s for s in shapes if poses[s] is None]
    if missing:
        raise TargetError(f"no action or pose asset named {', '.join(missing)} (one pose per shape)")
    channels = {}
    for s, act in poses.items():
        at = act.frame_range[0]
        for fc in act.fcurves:
            channels.setdefault((fc.data_path, fc.array_index), {})[s] = fc.evaluate(at)
    points = _cue_points(scene, cues, start)
    current = obj.animation_data.action if obj.animation_data else None
    if current is not None and any(a is current for a in poses.values()):
        raise TargetError(f"{obj.name}'s current action is one of the poses; give the armature another action")
    for (path, index), values in sorted(channels.items()):
        constant_keys(obj, path, index, [(f, values.get(s, _rest_value(path, index))) for f, s in points],
                      name=f"{obj.name} lipsync", group="lipsync")
    return f" ({len(channels)} channels from {len(poses)} poses)"
