# fx_light_rig.gd — FxLightRig: the energy wave's light rig (kind 3 frames, PROTOCOL.md §7.7) as
# Godot OmniLights that follow it every frame, so the wave lights the scene around it in the
# rig's own colour and strength. The segments that light (strength > 0) are the wave's centre
# line; consecutive segments of one source are merged into at most max_lights lights, evenly
# (the default torus's 12 chords become 6 lights of 2 chords round the ring), each at the
# strength-weighted mean of its segments' middles. A light's energy is energy_per_strength ×
# its segments' summed strength × the rig's light_strength, so the pulse along a curve and the
# stream's light_strength show; its colour is the toon ramp's band for a surface that faces
# the light (m = 1: the default ramp's 0.2 + 0.8·color_energy). Until a frame's constants are
# known no light shows (the recipe: do not shade without them). Positions are the stream's
# scene units in the node's space: give the node the transform of the FxTexture that draws
# the stream (its fit_stream places the quad in the same units).
extends "fx_stream_node.gd"

export var max_lights := 8
# Light energy per unit of segment strength (the sources' coef units).
export var energy_per_strength := 0.05
# Each light's omni_range, world units.
export var light_range := 5.0
export var shadows := false

# The latest frame: segments that light, lights shown and their colour (sRGB, as Light takes
# it; the band is linear).
var lit_segments := 0
var lights_shown := 0
var light_color := Color(0, 0, 0)

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
	var groups := _groups(f.rig["segments"])
	lights_shown = int(min(groups.size(), max_lights)) if _constants != null else 0
	while _lights.size() < lights_shown:
		var l := OmniLight.new()
		add_child(l)
		_lights.append(l)
	if _constants != null:
		light_color = srgb(_constants["bands"].back()["rgb"]) # m_min ascend: the last applies at m = 1
	for i in range(_lights.size()):
		var l: OmniLight = _lights[i]
		l.visible = i < lights_shown
		if i >= lights_shown:
			continue
		l.transform.origin = groups[i]["at"]
		l.light_energy = energy_per_strength * groups[i]["strength"] * _constants["strength"]
		l.light_color = light_color
		l.omni_range = light_range
		l.shadow_enabled = shadows
	return true


# The lit segments in groups, strongest first: runs of consecutive segments of one source, cut
# into pieces of g segments, g the smallest that gives max_lights pieces or fewer; with more
# sources than lights, one piece a source, and the weakest pieces get no light.
# {at: Vector3, strength: float}.
func _groups(segments: Array) -> Array:
	var runs := []
	var key := []
	lit_segments = 0
	for s in segments:
		if not s["strength"] > 0.0:
			key = []
			continue
		lit_segments += 1
		if key != [s["source"], s["index"]]:
			key = [s["source"], s["index"]]
			runs.append([])
		runs.back().append(s)
	var longest := 0
	for r in runs:
		longest = max(longest, r.size())
	var g := 1
	while g < longest and _pieces(runs, g) > max_lights:
		g += 1
	var groups := []
	for r in runs:
		for i in range(0, r.size(), g):
			groups.append(_merge(r.slice(i, min(i + g, r.size()) - 1)))
	groups.sort_custom(self, "_stronger")
	return groups


static func _pieces(runs: Array, g: int) -> int:
	var n := 0
	for r in runs:
		n += (r.size() + g - 1) / g
	return n


static func _merge(segments: Array) -> Dictionary:
	var at := Vector3()
	var strength := 0.0
	for s in segments:
		at += segment_middle(s) * s["strength"]
		strength += s["strength"]
	return {"at": at / strength, "strength": strength}


func _stronger(a: Dictionary, b: Dictionary) -> bool:
	return a["strength"] > b["strength"]


# A linear colour in sRGB, the space of Light.light_color.
static func srgb(c: Color) -> Color:
	return Color(_srgb1(c.r), _srgb1(c.g), _srgb1(c.b))


static func _srgb1(v: float) -> float:
	v = clamp(v, 0.0, 1.0)
	return v * 12.92 if v <= 0.0031308 else 1.055 * pow(v, 1.0 / 2.4) - 0.055
