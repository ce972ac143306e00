# demo.gd — the demo scene's script: points the client at FXSTREAM_URL when that is set (else
# the Client node's url, fxstreamd's default), gives the flame the particle budget
# FXSTREAM_MAX_PARTICLES when that is set (else every particle; the panel changes it), turns
# the camera slowly around the scene, and with `--screenshot PATH` on the command line saves a
# picture once every stream has drawn and quits (tools/screenshot_godot.sh takes README's
# picture so). The demo's addons/fxstream is a link to clients/godot/addons/fxstream: copy the
# folder instead where links are not followed (Windows).
# The scene: the flame, and the energy wave (Wave, an FxTexture) with its light rig (Rig, an
# FxLightRig) under the same transform, so the rig's lights sit on the drawn ring; the stream's
# shadow plane (y = -9 in its units, × 0.3) falls on the ground. Its Environment uses the
# Linear tone map (the wave's material tone-maps itself, hue-preserving) and glow with an HDR
# threshold of 0.6, which gives the ring its halo.
# Start fxstreamd first (make run).
extends Spatial

var _shot := ""
var _t := 0.0


# Before the children's _ready: the flame subscribes with its budget, the panel shows it.
func _enter_tree() -> void:
	var budget := OS.get_environment("FXSTREAM_MAX_PARTICLES")
	if budget != "":
		$Flame.max_particles = int(budget)


func _ready() -> void:
	var url := OS.get_environment("FXSTREAM_URL")
	if url != "":
		$Client.url = url
		$Client.connect_to_server()
	var args := Array(OS.get_cmdline_args())
	var i := args.find("--screenshot")
	if i >= 0 and i + 1 < args.size():
		_shot = args[i + 1]


func _process(delta: float) -> void:
	_t += delta
	$CameraPivot.rotation.y = 0.35 * sin(0.15 * _t)
	if _shot != "" and _t > 4.0 and $Flame.particles > 0 and $Wave.width > 0 and $Rig.lights_shown > 0:
		var img := get_viewport().get_texture().get_data()
		img.flip_y()
		img.save_png(_shot)
		print("saved ", _shot)
		get_tree().quit()
