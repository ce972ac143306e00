# fx_flame.gd — FxFlame: the `flame` effect's particles, drawn every frame in the node's own
# space. The frame's texture goes to the GPU as it came (FxFrame.image: no loop over particles
# in GDScript); one MultiMesh instance per particle reads its texel in flame.shader, a camera
# facing additive sprite in the page's hdr colours; with velocity_lines, a second MultiMesh of
# line segments reads the velocities (the stream's `velocities` parameter must be on).
# With a particle budget (max_particles) a frame may be a subset of the stream's particles, each
# standing for total / count of them (PROTOCOL.md §3.5): their spacing is (total / count)^(1/3)
# times the stream's, so the sprites grow by that factor (particle_scale) and each adds as much
# again of light, as the browser page draws it, and the flame keeps its extent and brightness.
# A stream of another resolution (its h: a finer one has more, smaller particles in the same
# flame) draws each sprite's light in proportion to a particle's volume, (spacing / the default
# stream's)^3 (resolution_scale), so at the node's fixed sprite size the flame is as bright.
#
# Units: the stream's positions are metres × its `space_scale`, with its `up` parameter as
# the vertical; the node shows them in metres with `up` along its +Y, so its transform
# places, turns and scales the flame like any other node (a scale of 1 is life size).
extends "fx_stream_node.gd"

const FLAME_SHADER = preload("flame.shader")
const LINES_SHADER = preload("flame_lines.shader")
# digest 002 §4.2: chromaticity-normalised blackbody colours, linear RGB, 800 .. 3000 K.
const BLACKBODY_T = [800, 1000, 1200, 1500, 1800, 2000, 2200, 2500, 2800, 3000]
const BLACKBODY_RGB = [Color(1, 0.059, 0), Color(1, 0.116, 0), Color(1, 0.189, 0), Color(1, 0.314, 0.009),
		Color(1, 0.45, 0.088), Color(1, 0.543, 0.172), Color(1, 0.638, 0.283), Color(1, 0.778, 0.503),
		Color(1, 0.914, 0.783), Color(1, 1, 1)]

# The particle spacing `exposure` is set for: the default stream's (particle_diameter 0.5 × h 3.5 mm).
const D_REF := 0.00175

# Sprite diameter in metres.
export var sprite_size := 0.01 setget set_sprite_size
export var exposure := 1.0 setget set_exposure
# The temperature drawn white.
export var white_temperature := 4000.0 setget set_white_temperature
export var velocity_lines := false
# Seconds of each particle's path a velocity line shows.
export var velocity_scale := 0.005 setget set_velocity_scale

# Particles drawn (the MultiMesh's visible instances): the latest frame's count.
var particles := 0
# The stream's particles in that frame: its header's total when it is a budget's subset, else
# the count drawn.
var stream_particles := 0
# What each drawn particle's sprite size and light are multiplied by: (stream_particles /
# particles)^(1/3), 1 for a whole frame.
var particle_scale := 1.0
# What each sprite's light is multiplied by for the stream's resolution: (its particle spacing /
# D_REF)^3, 1 for the default stream.
var resolution_scale := 1.0
# The sprite material's uniforms as last set (the engine keeps them; its headless renderer does not).
var sprite_uniforms := {}

var _stage := Spatial.new()        # the stream's frame: up to +Y, metres
var _sprites := MultiMeshInstance.new()
var _lines := MultiMeshInstance.new()
var _sprite_mat := ShaderMaterial.new()
var _line_mat := ShaderMaterial.new()
var _texture := ImageTexture.new()
var _space_scale := 1.0


func _init() -> void:
	stream = "flame"


func _ready() -> void:
	add_child(_stage)
	var ramp := _blackbody_texture()
	_sprite_mat.shader = FLAME_SHADER
	_line_mat.shader = LINES_SHADER
	for m in [_sprite_mat, _line_mat]:
		m.set_shader_param("particles", _texture)
		m.set_shader_param("blackbody", ramp)
	_sprites.multimesh = _multimesh(_quad_mesh())
	_sprites.material_override = _sprite_mat
	_lines.multimesh = _multimesh(_line_mesh())
	_lines.material_override = _line_mat
	_stage.add_child(_sprites)
	_stage.add_child(_lines)
	_apply_look()


func set_sprite_size(v: float) -> void:
	sprite_size = v
	_apply_look()


func set_exposure(v: float) -> void:
	exposure = v
	_apply_look()


func set_white_temperature(v: float) -> void:
	white_temperature = v
	_apply_look()


func set_velocity_scale(v: float) -> void:
	velocity_scale = v
	_apply_look()


func _apply_look() -> void:
	_sprite_uniform("size", sprite_size * _space_scale * particle_scale)
	_sprite_uniform("exposure", exposure * particle_scale * resolution_scale)
	_line_mat.set_shader_param("velocity_scale", velocity_scale)
	for m in [_sprite_mat, _line_mat]:
		m.set_shader_param("t_white", white_temperature)
		m.set_shader_param("t_ambient", float(stream_params.get("T_amb", 300.0)))


func _sprite_uniform(name: String, value) -> void:
	_sprite_mat.set_shader_param(name, value)
	sprite_uniforms[name] = value


func _on_stream_params(doc: Dictionary) -> void:
	_space_scale = float(doc.get("space_scale", 1.0))
	resolution_scale = pow(float(doc.get("particle_diameter", 0.5)) * float(doc.get("h", 0.0035)) / D_REF, 3.0)
	var basis := up_to_y(vec3_of(doc.get("up"), Vector3(0, 0, 1)))
	_stage.transform = Transform(basis.scaled(Vector3.ONE / _space_scale), Vector3())
	_apply_look()


func _on_stream_frame(f) -> bool:
	if f.kind != f.KIND_PARTICLES or f.image == null:
		return false
	_grow(f.count)
	if _texture.get_width() == f.image.get_width() and _texture.get_height() == f.image.get_height():
		_texture.set_data(f.image)
	else:
		_texture.create_from_image(f.image, 0) # texels as sent: no filtering, mipmaps or repeat
	for m in [_sprite_mat, _line_mat]:
		m.set_shader_param("origin", f.origin)
		m.set_shader_param("width", f.width)
	_line_mat.set_shader_param("rows", f.rows)
	particles = f.count
	stream_particles = int(max(f.total, f.count))
	var grow := pow(float(f.total) / f.count, 1.0 / 3.0) if f.total > 0 and f.count > 0 else 1.0
	if grow != particle_scale:
		particle_scale = grow
		_apply_look()
	var pad := Vector3.ONE * sprite_size * _space_scale * particle_scale
	var box := AABB(f.origin - f.extent - pad, 2.0 * (f.extent + pad))
	if velocity_lines and f.velocities:
		box = box.grow(velocity_scale * 20.0 * _space_scale) # a line reaches out by its velocity
	_sprites.multimesh.mesh.custom_aabb = box
	_lines.multimesh.mesh.custom_aabb = box
	_sprites.multimesh.visible_instance_count = f.count
	_lines.multimesh.visible_instance_count = f.count if velocity_lines and f.velocities else 0
	return true


# Room for n instances in both MultiMeshes (grown by half again, never shrunk). New instances
# start with identity transforms, which the shaders leave alone: they place each instance.
func _grow(n: int) -> void:
	if n <= _sprites.multimesh.instance_count:
		return
	var cap := int(max(n * 3 / 2, 1024))
	_sprites.multimesh.instance_count = cap
	_lines.multimesh.instance_count = cap


static func _multimesh(mesh: Mesh) -> MultiMesh:
	var mm := MultiMesh.new()
	mm.transform_format = MultiMesh.TRANSFORM_3D
	mm.mesh = mesh
	mm.visible_instance_count = 0
	return mm


# A unit quad centred on the origin, the sprite the shader turns to the camera.
static func _quad_mesh() -> ArrayMesh:
	var arrays := []
	arrays.resize(Mesh.ARRAY_MAX)
	arrays[Mesh.ARRAY_VERTEX] = PoolVector3Array([Vector3(-0.5, -0.5, 0), Vector3(0.5, -0.5, 0),
			Vector3(0.5, 0.5, 0), Vector3(-0.5, 0.5, 0)])
	arrays[Mesh.ARRAY_TEX_UV] = PoolVector2Array([Vector2(0, 1), Vector2(1, 1), Vector2(1, 0), Vector2(0, 0)])
	arrays[Mesh.ARRAY_INDEX] = PoolIntArray([0, 1, 2, 0, 2, 3])
	var m := ArrayMesh.new()
	m.add_surface_from_arrays(Mesh.PRIMITIVE_TRIANGLES, arrays)
	return m


# A segment from x = 0 to x = 1: flame_lines.shader moves its ends.
static func _line_mesh() -> ArrayMesh:
	var arrays := []
	arrays.resize(Mesh.ARRAY_MAX)
	arrays[Mesh.ARRAY_VERTEX] = PoolVector3Array([Vector3(0, 0, 0), Vector3(1, 0, 0)])
	var m := ArrayMesh.new()
	m.add_surface_from_arrays(Mesh.PRIMITIVE_LINES, arrays)
	return m


static func _blackbody_texture() -> GradientTexture:
	var g := Gradient.new()
	g.offsets = PoolRealArray()
	g.colors = PoolColorArray()
	for i in range(BLACKBODY_T.size()):
		g.add_point((BLACKBODY_T[i] - 800.0) / 2200.0, BLACKBODY_RGB[i])
	var t := GradientTexture.new()
	t.gradient = g
	t.width = 256
	return t
