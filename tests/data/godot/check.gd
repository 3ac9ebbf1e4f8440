extends SceneTree
# Run by tests/test_godot.py in Godot 3's headless server: the player's cell at chosen times
# (res://times.json), then the time and cell its _process shows while the speech plays.
var player
var started = 0
var clocked = []

func _wav(path):
	var f = File.new()
	f.open(path, File.READ)
	var bytes = f.get_buffer(f.get_len())
	f.close()
	var stream = AudioStreamSample.new()
	stream.format = AudioStreamSample.FORMAT_16_BITS
	stream.mix_rate = bytes[24] + 256 * bytes[25] + 65536 * bytes[26]
	stream.stereo = bytes[22] == 2
	var at = 12
	while at + 8 <= bytes.size():  # RIFF chunks: find "data"
		var size = bytes[at + 4] + 256 * bytes[at + 5] + 65536 * bytes[at + 6] + 16777216 * bytes[at + 7]
		if bytes.subarray(at, at + 3).get_string_from_ascii() == "data":
			stream.data = bytes.subarray(at + 8, at + 8 + size - 1)
			break
		at += 8 + size
	return stream

func _init():
	var f = File.new()
	f.open("res://times.json", File.READ)
	var times = JSON.parse(f.get_as_text()).result
	f.close()
	player = load("res://lipsync_player.gd").new()
	player.atlas_path = "res://mouth/mouth.json"
	player.frames_path = "res://mouth/hello.frames.json"
	player.autoplay = false
	var voice = AudioStreamPlayer.new()
	voice.name = "Voice"
	voice.stream = _wav("res://hello.wav")
	player.add_child(voice)
	get_root().add_child(player)
	var shown = []
	for t in times:
		var c = player.show_time(t)
		var r = player.mouth.region_rect
		shown.append({"t": t, "cell": c, "rect": [r.position.x, r.position.y, r.size.x, r.size.y]})
	var m = player.mouth
	print("LIPSYNC " + JSON.print({"shown": shown, "mouth_pos": [m.position.x, m.position.y],
		"mouth_scale": [m.scale.x, m.scale.y], "texture": [m.texture.get_width(), m.texture.get_height()],
		"base": [player.base.texture.get_width(), player.base.texture.get_height()] if player.base.texture else null,
		"stream_seconds": voice.stream.get_length()}))
	voice.play()
	started = OS.get_ticks_msec()

func _idle(_delta):
	# the time and cell the player's _process chose on the audio clock in the last frame
	if player.voice.playing:
		clocked.append({"time": player.time, "cell": player.cell})
	if OS.get_ticks_msec() - started > 8000 or (clocked.size() > 0 and not player.voice.playing):
		print("CLOCKED " + JSON.print(clocked))
		quit()
	return false
