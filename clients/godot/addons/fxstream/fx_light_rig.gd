# fx_light_rig.gd — FxLightRig: the energy wave's light rig (kind 3 frames, PROTOCOL.md §7.7) as
# Godot OmniLights that follow it every frame, so the wave lights the scene around it. Each
# segment that lights (strength > 0) is a light source along the wave's centre line: the
# max_lights strongest become lights at their segments' middles (a point or an endless line:
# its start point), with energy light_energy × strength / the strongest's, in light_color (or,
# with use_band_color, the stream's toon ramp's brightest band). Positions are the stream's
# scene units in the node's space: scale and place the node as the stream's texture is placed
# (FxTexture).
extends "fx_stream_node.gd"

export var max_lights := 8
export var light_energy := 2.0
# Each light's omni_range.
export var light_range := 5.0
export var light_color := Color(1.0, 0.55, 0.2)
export var use_band_color := false
export var shadows := false

# The latest frame: segments that light, and the lights shown.
var lit_segments := 0
var lights_shown := 0

var _lights := []
var _constants = null
var _constants_id := -1


func _init() -> void:
	stream = "energy"


func _on_stream_frame(f) -> bool:
	if f.kind != f.KIND_LIGHT_RIG or f.rig == null:
		return false
	if f.rig["constants"] != null:
		_constants = f.rig["constants"]
		_constants_id = f.rig["constants_id"]
	elif f.rig["constants_id"] != _constants_id:
		_constants = null # constants changed in a frame that does not carry them (§7.7)
	var lit := []
	for s in f.rig["segments"]:
		if s["strength"] > 0.0:
			lit.append(s)
	lit.sort_custom(self, "_stronger")
	lit_segments = lit.size()
	lights_shown = int(min(lit.size(), max_lights))
	while _lights.size() < lights_shown:
		var l := OmniLight.new()
		add_child(l)
		_lights.append(l)
	var colour := _band_color() if use_band_color else light_color
	for i in range(_lights.size()):
		var l: OmniLight = _lights[i]
		l.visible = i < lights_shown
		if i >= lights_shown:
			continue
		var s: Dictionary = lit[i]
		l.transform.origin = _middle(s)
		l.light_energy = light_energy * s["strength"] / lit[0]["strength"]
		l.light_color = colour
		l.omni_range = light_range
		l.shadow_enabled = shadows
	return true


func _stronger(a: Dictionary, b: Dictionary) -> bool:
	return a["strength"] > b["strength"]


# The middle of a segment's span, or its start where the span is endless.
static func _middle(s: Dictionary) -> Vector3:
	var lo: float = s["a_lo"]
	var hi: float = s["a_hi"]
	var a := 0.0
	if not is_inf(lo) and not is_inf(hi):
		a = 0.5 * (lo + hi)
	return s["c"] + s["d"] * a


func _band_color() -> Color:
	if _constants == null or _constants["bands"].empty():
		return light_color
	var best: Color = _constants["bands"][0]["rgb"]
	for b in _constants["bands"]:
		if b["rgb"].v > best.v:
			best = b["rgb"]
	return best
