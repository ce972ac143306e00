# fx_texture.gd — FxTexture: a texture stream (the `energy_wave` effect by default) on a quad
# of `size` metres facing the node's +Z, as an additive emissive material (wave.shader) that
# Godot's glow picks up. Each frame's texels (FxFrame.image) replace the texture's data
# (ImageTexture.set_data, no loop over pixels). Use `texture` on any other material too.
extends "fx_stream_node.gd"

const WAVE_SHADER = preload("wave.shader")

export var size := Vector2(1, 1) setget set_size
export var energy := 2.0 setget set_energy
export var tint := Color(1, 1, 1) setget set_tint
# Colours of a one-channel texture from B = 0 to 1 (default: black, deep orange, white).
export var ramp: Gradient = null setget set_ramp

# The stream's texture (filtered), and the latest frame's size and channels.
var texture := ImageTexture.new()
var width := 0
var height := 0
var channels := 0

var _mesh := MeshInstance.new()
var _mat := ShaderMaterial.new()


func _init() -> void:
	stream = "energy"


func _ready() -> void:
	var quad := QuadMesh.new()
	quad.size = size
	_mesh.mesh = quad
	_mat.shader = WAVE_SHADER
	_mat.set_shader_param("wave", texture)
	_mesh.material_override = _mat
	add_child(_mesh)
	if ramp == null:
		ramp = Gradient.new()
		ramp.offsets = PoolRealArray([0.0, 0.5, 1.0])
		ramp.colors = PoolColorArray([Color(0, 0, 0), Color(1.0, 0.35, 0.05), Color(1, 1, 1)])
	set_ramp(ramp)
	set_energy(energy)
	set_tint(tint)


func set_size(v: Vector2) -> void:
	size = v
	if _mesh.mesh != null:
		_mesh.mesh.size = v


func set_energy(v: float) -> void:
	energy = v
	_mat.set_shader_param("energy", v)


func set_tint(v: Color) -> void:
	tint = v
	_mat.set_shader_param("tint", v)


func set_ramp(g: Gradient) -> void:
	ramp = g
	var t := GradientTexture.new()
	t.gradient = g
	_mat.set_shader_param("ramp", t)


func _on_stream_frame(f) -> bool:
	if f.kind != f.KIND_TEXTURE or f.image == null:
		return false
	if width == f.width and height == f.rows and channels == f.channels:
		texture.set_data(f.image)
	else:
		texture.create_from_image(f.image, Texture.FLAG_FILTER)
	width = f.width
	height = f.rows
	channels = f.channels
	_mat.set_shader_param("one_channel", channels == 1)
	return true
