# fx_eye.gd — FxEye: the compound eye in mode `bake` (PROTOCOL.md §11.3): the view texture the
# daemon bakes (kind 2, RGBA) on the model it was baked for, built here as the daemon builds it
# (server/effects/eye_model.c: the front half of an ellipsoid with stereographic texture
# coordinates, or the 2 × 2 plane; an OBJ model of the daemon's shows on the plane, its uv
# square). The bake is already shaded (seen from the stream's `eye`), so the material is
# unshaded. Model units are the node's; +Z is the model's front. The stream's `mode` must be
# "bake" (set it on the stream, or use FxStreamClient.set_params).
extends "fx_stream_node.gd"

const RINGS = 32
const SEGMENTS = 64
const ELLIPSOIDS = {"hemisphere": Vector3(1, 1, 1), "insect_eye": Vector3(0.8, 0.65, 1.0)}

# The latest bake's size.
var width := 0
var height := 0
var texture := ImageTexture.new()

var _mesh := MeshInstance.new()
var _mat := SpatialMaterial.new()
var _model := ""


func _init() -> void:
	stream = "eye"


func _ready() -> void:
	_mat.flags_unshaded = true
	_mat.params_cull_mode = SpatialMaterial.CULL_DISABLED
	_mat.albedo_texture = texture
	_mesh.material_override = _mat
	add_child(_mesh)
	_build("hemisphere")


func _on_stream_params(doc: Dictionary) -> void:
	_build(str(doc.get("model", "hemisphere")))


func _on_stream_frame(f) -> bool:
	if f.kind != f.KIND_TEXTURE or f.image == null or f.channels != 4:
		return false
	if width == f.width and height == f.rows:
		texture.set_data(f.image)
	else:
		texture.create_from_image(f.image, Texture.FLAG_FILTER | Texture.FLAG_MIPMAPS)
	width = f.width
	height = f.rows
	return true


func _build(model: String) -> void:
	if model == _model:
		return
	_model = model
	_mesh.mesh = _ellipsoid(ELLIPSOIDS[model]) if ELLIPSOIDS.has(model) else _plane()


# eye_model.c's eye_ellipsoid_vertex: texture row 0 is the bake's v = 1 (§11.3), so v flips.
static func _vertex(st: SurfaceTool, ax: Vector3, ring: int, seg: int) -> void:
	var th := 0.5 * PI * ring / RINGS
	var ph := 2.0 * PI * seg / SEGMENTS
	var s := Vector3(sin(th) * cos(ph), sin(th) * sin(ph), cos(th))
	st.add_uv(Vector2(0.5 + 0.5 * s.x / (1.0 + s.z), 0.5 - 0.5 * s.y / (1.0 + s.z)))
	st.add_normal((s / ax).normalized())
	st.add_vertex(s * ax)


static func _ellipsoid(ax: Vector3) -> ArrayMesh:
	var st := SurfaceTool.new()
	st.begin(Mesh.PRIMITIVE_TRIANGLES)
	for r in range(RINGS):
		for s in range(SEGMENTS):
			for q in [[r, s], [r + 1, s + 1], [r + 1, s], [r, s], [r, s + 1], [r + 1, s + 1]]:
				_vertex(st, ax, q[0], q[1])
	st.index()
	return st.commit()


static func _plane() -> ArrayMesh:
	var st := SurfaceTool.new()
	st.begin(Mesh.PRIMITIVE_TRIANGLES)
	for c in [Vector2(0, 0), Vector2(1, 1), Vector2(1, 0), Vector2(0, 0), Vector2(0, 1), Vector2(1, 1)]:
		st.add_uv(Vector2(c.x, 1.0 - c.y))
		st.add_normal(Vector3(0, 0, 1))
		st.add_vertex(Vector3(2.0 * c.x - 1.0, 2.0 * c.y - 1.0, 0.0))
	return st.commit()
