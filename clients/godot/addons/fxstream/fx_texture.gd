# fx_texture.gd — FxTexture: a texture stream (the `energy_wave` effect by default) on a quad, as
# an additive emissive material (wave.shader) that draws it as the browser page does
# (clients/web/src/wave.js): coloured by the stream's own color_energy / color_background,
# display levels over the floor F the node measures on each frame's border, a window that
# fades the quad to nothing before its edge, and the hue-preserving glow tone map; Godot's
# glow (WorldEnvironment) adds the halo. Each frame's texels (FxFrame.image) replace the
# texture's data (ImageTexture.set_data, no loop over pixels).
#
# Placement: with fit_stream (the default) the quad is the stream's billboard in the stream's
# scene units, moved along its view ray to the depth of the light rig's centre line and scaled
# to match (as the page's toon scene places it), so an FxLightRig with the same transform has
# its lights on the wave's ring; scale and place the node to put the wave in your scene.
# Without the light rig the quad stays at the stream's `center`. With fit_stream off the quad
# is `size` wide and high, centred on the node. With `billboard` it faces the camera, else the
# node's +Z. Use `texture` on any other material too (raw B, HDR).
extends "fx_stream_node.gd"

const WAVE_SHADER = preload("wave.shader")
# The share of rows and columns on each side the floor is measured on (wave.js).
const BORDER_SHARE = 0.02

export var fit_stream := true setget set_fit_stream
export var size := Vector2(1, 1) setget set_size
export var billboard := true setget set_billboard
# The page's display levels (its Display sliders): floor_level removes a little more than the
# border's median, contrast steepens the 1/d field's log profile into a glow, gain scales it.
export var floor_level := 1.15 setget set_floor_level
export var gain := 1.5 setget set_gain
export var contrast := 2.0 setget set_contrast
# Linear scale before the tone map.
export var exposure := 1.0 setget set_exposure
# The hue-preserving glow tone map in the material (use the Environment's Linear tone map), or
# linear HDR out for the Environment's own tone map.
export var tone_map := true setget set_tone_map

# The stream's texture (filtered), and the latest frame's size and channels.
var texture := ImageTexture.new()
var width := 0
var height := 0
var channels := 0
# The floor F of the latest frame: the median B (A for RGBA) over its border.
var floor_value := 1.0
# Where the quad is in the node's space (its middle), and its size there.
var quad_center := Vector3()
var quad_size := Vector2(1, 1)

# The material's uniforms as last set (the engine keeps them; its headless renderer does not).
var uniforms := {}

var _mesh := MeshInstance.new()
var _mat := ShaderMaterial.new()
var _depth := 1.0   # the quad's depth along the stream's view ray, a multiple of eye → center


func _init() -> void:
	stream = "energy"
	_mat.shader = WAVE_SHADER
	_uniform("wave", texture)
	_apply_look()


func _ready() -> void:
	_mesh.mesh = QuadMesh.new()
	_mesh.material_override = _mat
	add_child(_mesh)
	_place()


func set_fit_stream(v: bool) -> void:
	fit_stream = v
	_place()


func set_size(v: Vector2) -> void:
	size = v
	_place()


func set_billboard(v: bool) -> void:
	billboard = v
	_apply_look()


func set_floor_level(v: float) -> void:
	floor_level = v
	_apply_look()


func set_gain(v: float) -> void:
	gain = v
	_apply_look()


func set_contrast(v: float) -> void:
	contrast = max(v, 0.01)
	_apply_look()


func set_exposure(v: float) -> void:
	exposure = v
	_apply_look()


func set_tone_map(v: bool) -> void:
	tone_map = v
	_apply_look()


func _apply_look() -> void:
	_uniform("billboard", billboard)
	_uniform("floor_k", floor_level)
	_uniform("gain", gain)
	_uniform("contrast", contrast)
	_uniform("exposure", exposure)
	_uniform("tone_map", tone_map)


func _on_stream_params(doc: Dictionary) -> void:
	_uniform("color_energy", vec3_of(doc.get("color_energy"), Vector3(1, 1, 1)))
	_uniform("color_background", vec3_of(doc.get("color_background"), Vector3()))
	_place()


func _on_stream_frame(f) -> bool:
	if f.kind == f.KIND_LIGHT_RIG and f.rig != null:
		_depth = _rig_depth(f.rig["segments"])
		_place()
		return false # the texture frame stays last_frame
	if f.kind != f.KIND_TEXTURE or f.image == null:
		return false
	if width == f.width and height == f.rows and channels == f.channels:
		texture.set_data(f.image)
	else:
		texture.create_from_image(f.image, Texture.FLAG_FILTER)
	width = f.width
	height = f.rows
	channels = f.channels
	floor_value = max(border_median(f.image, 0 if channels == 1 else 3), 1e-4)
	_uniform("one_channel", channels == 1)
	_uniform("floor_b", floor_value)
	_place()
	return true


func _uniform(name: String, value) -> void:
	_mat.set_shader_param(name, value)
	uniforms[name] = value


# The quad's middle and size from the stream's camera (eye, center, size, and the texture's
# aspect) at _depth, or `size` at the node's origin.
func _place() -> void:
	if _mesh.mesh == null:
		return
	quad_center = Vector3()
	quad_size = size
	if fit_stream and stream_params.has("size"):
		var eye := vec3_of(stream_params.get("eye"), Vector3(0, 0, 1))
		var center := vec3_of(stream_params.get("center"), Vector3())
		var w := float(stream_params["size"]) * _depth
		var aspect := float(height) / width if width > 0 else float(stream_params.get("height", 1)) / float(stream_params.get("width", 1))
		quad_center = eye + (center - eye) * _depth
		quad_size = Vector2(w, w * aspect)
	_mesh.mesh.size = quad_size
	_mesh.transform.origin = quad_center
	# a billboard turns out of its flat bounding box
	_mesh.extra_cull_margin = quad_size.length() * 0.5 if billboard else 0.0


# The depth of the light rig's centre line along the stream's view ray, as a multiple of
# eye → center: the mean of its segments' middles (a segment without ends: its start).
func _rig_depth(segments: Array) -> float:
	if segments.empty() or not stream_params.has("eye"):
		return _depth
	var mid := Vector3()
	for s in segments:
		mid += segment_middle(s)
	mid /= segments.size()
	var eye := vec3_of(stream_params.get("eye"), Vector3(0, 0, 1))
	var ray := vec3_of(stream_params.get("center"), Vector3()) - eye
	return max(0.05, (mid - eye).dot(ray) / ray.length_squared())


# The median of one channel over the image's outer 2% of rows and columns (at least one), as
# wave.js measures the floor. The engine cuts the border strips and converts them to 32-bit
# floats; their bytes become one PoolRealArray (var2bytes' layout: type, count, values) that
# Array.sort orders, so no GDScript loop runs over texels of a one-channel image.
static func border_median(img: Image, channel: int) -> float:
	var w := img.get_width()
	var h := img.get_height()
	var m := int(max(1, round(BORDER_SHARE * min(w, h))))
	var rects := [Rect2(0, 0, w, h)] # too small for a border: all of it
	if w > 2 * m and h > 2 * m:
		rects = [Rect2(0, 0, w, m), Rect2(0, h - m, w, m), Rect2(0, m, m, h - 2 * m), Rect2(w - m, m, m, h - 2 * m)]
	var bytes := PoolByteArray()
	for r in rects:
		var strip := img.get_rect(r)
		strip.convert(Image.FORMAT_RF if channel == 0 else Image.FORMAT_RGBAF)
		bytes.append_array(strip.get_data())
	var sp := StreamPeerBuffer.new()
	sp.put_32(TYPE_REAL_ARRAY)
	sp.put_32(bytes.size() / 4)
	sp.put_data(bytes)
	var all: PoolRealArray = bytes2var(sp.data_array)
	var values := []
	if channel == 0:
		values = Array(all)
	else:
		for i in range(channel, all.size(), 4):
			values.append(all[i])
	if values.empty():
		return 0.0
	values.sort()
	return values[values.size() >> 1]
