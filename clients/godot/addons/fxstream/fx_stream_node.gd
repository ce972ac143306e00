# fx_stream_node.gd — what every fxstream node shares: it finds its FxStreamClient (client_path),
# subscribes to its stream in the engine encoding while it is in the tree, follows the stream's
# parameters (a `get` on every connection, then the params events) and hands each frame of
# its stream to _on_stream_frame. FxFlame, FxTexture, FxLightRig and FxEye extend it.
extends Spatial

export(NodePath) var client_path := NodePath("..")
export var stream := ""
# Steps a second at most (0: the stream's own fps).
export var max_fps := 0.0
# Particles a frame at most (0: every particle), for a game that cannot draw or download a large
# flame: the daemon sends a subset drawn in proportion (PROTOCOL.md §3.5). Set at run time, it
# subscribes again with the new budget. A daemon that offers no budgets (cluster mode) sends
# every particle; the client warns (budget_refused).
export var max_particles := 0 setget set_max_particles

# The stream's complete parameter document and revision, once known.
var stream_params := {}
var stream_rev := 0
# The newest frame drawn, and this node's work on it (microseconds).
var last_frame = null
var last_update_usec := 0

var client: Node = null
var _subscribed := false


func _ready() -> void:
	client = get_node_or_null(client_path)
	if client == null or not client.has_signal("frame_received"):
		push_warning("fxstream: %s: client_path %s is not an FxStreamClient" % [name, client_path])
		client = null
		return
	client.connect("frame_received", self, "_on_frame_received")
	client.connect("params", self, "_on_params")
	client.connect("connected", self, "_on_connected")
	_subscribe()


# Back in the tree after a removal (_ready runs only once).
func _enter_tree() -> void:
	if client != null and not _subscribed:
		_subscribe()


func _exit_tree() -> void:
	if client != null and _subscribed:
		client.unsubscribe(stream)
		_subscribed = false


func set_max_particles(n: int) -> void:
	max_particles = n
	if client != null and _subscribed:
		client.set_max_particles(stream, n)


func _subscribe() -> void:
	client.subscribe(stream, max_fps, client.ENCODING_ENGINE, max_particles)
	_subscribed = true
	if client.is_open():
		client.get_params(stream)


func _on_connected(_hello) -> void:
	client.get_params(stream)


func _on_params(s: String, rev: int, doc: Dictionary, _request_id: int) -> void:
	if s != stream or doc.empty():
		return
	stream_params = doc
	stream_rev = rev
	_on_stream_params(doc)


func _on_frame_received(s: String, frame) -> void:
	if s != stream:
		return
	var t0 := OS.get_ticks_usec()
	if _on_stream_frame(frame):
		last_frame = frame
		last_update_usec = OS.get_ticks_usec() - t0


# Overridden: the stream's parameters changed (or arrived).
func _on_stream_params(_doc: Dictionary) -> void:
	pass


# Overridden: a frame of the stream; true when the node used it.
func _on_stream_frame(_frame) -> bool:
	return false


# The rotation that takes the stream's `up` axis to the node's +Y (Godot's up), so a stream in
# any frame stands upright under the node.
static func up_to_y(up: Vector3) -> Basis:
	up = up.normalized()
	var axis := up.cross(Vector3.UP)
	if axis.length() < 1e-6:
		return Basis() if up.y > 0 else Basis(Vector3.RIGHT, PI)
	return Basis(axis.normalized(), acos(clamp(up.dot(Vector3.UP), -1.0, 1.0)))


static func vec3_of(v, fallback: Vector3) -> Vector3:
	if typeof(v) == TYPE_ARRAY and v.size() == 3:
		return Vector3(v[0], v[1], v[2])
	return fallback


# The middle of a light-rig segment's span, or its start where the span is endless.
static func segment_middle(s: Dictionary) -> Vector3:
	var lo: float = s["a_lo"]
	var hi: float = s["a_hi"]
	var a := 0.0
	if not is_inf(lo) and not is_inf(hi):
		a = 0.5 * (lo + hi)
	return s["c"] + s["d"] * a
