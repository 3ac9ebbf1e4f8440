extends Node2D
# Plays a lipsync sprite atlas (`lipsync atlas` + `lipsync cues --format atlas`) on the
# speech's clock. Godot 3.x (GDScript 1); tested headless with Godot 3.2 (tests/test_godot.py).
#
# Put this script on a Node2D at the frame's top-left corner, with an AudioStreamPlayer child
# "Voice" holding the speech. It adds two Sprites: the atlas base (the part of the frame that
# never changes) and the mouth cell above it. At time t of the speech it shows
#     cells[frames[n]] with n = clamp(floor(t * fps), 0, count - 1)
# exactly as lipsync's own player page does. Import mouth.png with Filter off or on, mipmaps
# off and no lossy compression, and assign it to `texture` (and mouth.base.png to
# `base_texture`) for exported games; without them the PNGs beside the atlas JSON are read
# at run time, which works in the editor and with files outside the export. Add *.json to
# Project > Export > Resources > "Filters to export non-resource files".

export(String, FILE, "*.json") var atlas_path = "res://mouth/mouth.json"
export(String, FILE, "*.json") var frames_path = "res://mouth/speech.frames.json"
export(NodePath) var voice_path = NodePath("Voice")
export(Texture) var texture = null
export(Texture) var base_texture = null
export(bool) var autoplay = true

var atlas = {}
var frames = {}
var cell = -1  # the cell shown
var time = 0.0  # the time it shows (seconds of the speech)
var mouth = Sprite.new()
var base = Sprite.new()
var voice = null


func _read_json(path):
	var file = File.new()
	if file.open(path, File.READ) != OK:
		push_error("lipsync: cannot read " + path)
		return {}
	var parsed = JSON.parse(file.get_as_text())
	file.close()
	if parsed.error != OK or typeof(parsed.result) != TYPE_DICTIONARY:
		push_error("lipsync: %s: line %d: %s" % [path, parsed.error_line, parsed.error_string])
		return {}
	return parsed.result


func _image(path):
	var img = Image.new()
	if img.load(path) != OK:
		push_error("lipsync: cannot load " + path)
		return null
	var tex = ImageTexture.new()
	tex.create_from_image(img, 0)  # no mipmaps, no filter: cells are drawn at frame size
	return tex


func _ready():
	atlas = _read_json(atlas_path)
	frames = _read_json(frames_path)
	if atlas.get("format") != "lipsync-atlas" or int(atlas.get("version", 0)) > 1:
		push_error("lipsync: %s is not a lipsync atlas of version 1" % atlas_path)
		return
	if frames.get("format") != "lipsync-atlas-frames" or int(frames.get("version", 0)) > 1:
		push_error("lipsync: %s is not a lipsync frames.json of version 1" % frames_path)
		return
	var folder = atlas_path.get_base_dir()
	var back = 1.0 / float(atlas["scale"])  # cells and base are drawn at frame size
	base.centered = false
	base.scale = Vector2(back, back)
	if atlas["base"] != null:
		base.texture = base_texture if base_texture != null else _image(folder.plus_file(atlas["base"]))
	mouth.centered = false
	mouth.region_enabled = true
	mouth.position = Vector2(atlas["region"][0], atlas["region"][1])
	mouth.scale = Vector2(back, back)
	mouth.texture = texture if texture != null else _image(folder.plus_file(atlas["image"]))
	add_child(base)
	add_child(mouth)
	voice = get_node_or_null(voice_path)
	show_time(0.0)
	if autoplay and voice != null and voice.stream != null:
		voice.play()


# The frame shown at time t (seconds) of the speech.
func frame_at(t):
	var count = frames["frames"].size()
	return int(clamp(floor(t * float(frames["fps"])), 0, count - 1))


# Shows the cell of time t; returns the cell's index.
func show_time(t):
	time = t
	var c = int(frames["frames"][frame_at(t)])
	if c != cell:
		cell = c
		var r = atlas["cells"][c]["rect"]
		mouth.region_rect = Rect2(r[0], r[1], r[2], r[3])
	return c


# The speech's clock: the playback position corrected for the mix and output latency
# (Godot's audio-sync recipe); not the frame clock, which drifts from the sound.
func clock():
	return voice.get_playback_position() + AudioServer.get_time_since_last_mix() - AudioServer.get_output_latency()


func _process(_delta):
	if voice != null and voice.playing:
		show_time(clock())
