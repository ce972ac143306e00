# tuning.gd — the demo's panel: a few sliders that `set` parameters of the flame and the energy
# wave, each stream's presets (`presets`, `preset_load`), and the flame's particle budget (the
# node's max_particles) with the particles drawn of the stream's. Other clients' changes move the
# sliders (params events); a refused value or budget shows the server's message.
extends PanelContainer

# [stream, parameter, component (-1: a number), label, min, max]
const SLIDERS = [
	["flame", "wind_velocity", 0, "flame: wind (m/s)", -4.0, 4.0],
	["flame", "time_scale", -1, "flame: time scale", 0.0, 2.0],
	["energy", "alpha", -1, "wave: alpha", 0.2, 4.0],
	["energy", "light_strength", -1, "wave: light strength", 0.0, 1.0],
]
const PRESETS = {"flame": "flame", "energy": "energy_wave"}
# The budget menu's choices (0: every particle); the daemon serves these steps as they are.
const BUDGETS = [0, 1000, 2000, 5000, 10000, 20000, 50000, 100000]

export(NodePath) var client_path := NodePath("../../Client")
export(NodePath) var flame_path := NodePath("../../Flame")

var _client: Node
var _sliders := {}        # "stream/param" -> HSlider
var _docs := {}           # stream -> its latest params document
var _pending := {}        # stream -> params to send (throttled)
var _menus := {}          # stream -> OptionButton
var _status := Label.new()
var _flame: Node
var _budget := OptionButton.new()
var _particles := Label.new()
var _since_send := 0.0


func _ready() -> void:
	_client = get_node(client_path)
	var box := VBoxContainer.new()
	add_child(box)
	for s in SLIDERS:
		var label := Label.new()
		label.text = s[3]
		box.add_child(label)
		var slider := HSlider.new()
		slider.min_value = s[4]
		slider.max_value = s[5]
		slider.step = (s[5] - s[4]) / 100.0
		slider.rect_min_size = Vector2(220, 0)
		slider.connect("value_changed", self, "_on_slider", [s])
		box.add_child(slider)
		_sliders[s[0] + "/" + s[1]] = slider
	for stream in PRESETS.keys():
		var menu := OptionButton.new()
		menu.add_item("%s presets" % stream)
		menu.connect("item_selected", self, "_on_preset", [stream])
		box.add_child(menu)
		_menus[stream] = menu
	_flame = get_node(flame_path)
	for n in BUDGETS:
		_budget.add_item("flame: every particle" if n == 0 else "flame: at most %d particles" % n)
	_budget.select(max(BUDGETS.find(_flame.max_particles), 0))
	_budget.connect("item_selected", self, "_on_budget")
	box.add_child(_budget)
	box.add_child(_particles)
	_status.autowrap = true
	_status.rect_min_size = Vector2(220, 0)
	box.add_child(_status)
	_client.connect("connected", self, "_on_connected")
	_client.connect("params", self, "_on_params")
	_client.connect("presets_received", self, "_on_presets")
	_client.connect("error", self, "_on_error")
	_client.connect("budget_refused", self, "_on_budget_refused")


func _on_connected(_hello) -> void:
	_status.text = "connected to %s" % _client.url
	for stream in PRESETS.keys():
		_client.get_params(stream)
	_client.presets()


func _on_params(stream: String, _rev: int, doc: Dictionary, _id: int) -> void:
	_docs[stream] = doc
	for s in SLIDERS:
		if s[0] == stream and doc.has(s[1]):
			var v = doc[s[1]]
			_sliders[stream + "/" + s[1]].set_block_signals(true)
			_sliders[stream + "/" + s[1]].value = v[s[2]] if s[2] >= 0 else v
			_sliders[stream + "/" + s[1]].set_block_signals(false)


func _on_slider(value: float, s: Array) -> void:
	var stream: String = s[0]
	var changes: Dictionary = _pending.get(stream, {})
	if s[2] >= 0: # one component of a vector: the rest as the stream has them
		var v: Array = (_docs.get(stream, {}).get(s[1], [0, 0, 0])).duplicate()
		v[s[2]] = value
		changes[s[1]] = v
	else:
		changes[s[1]] = value
	_pending[stream] = changes


# At most ten sets a second while a slider is dragged.
func _process(delta: float) -> void:
	_show_particles()
	_since_send += delta
	if _since_send < 0.1 or _pending.empty():
		return
	_since_send = 0.0
	for stream in _pending.keys():
		_client.set_params(stream, _pending[stream])
	_pending.clear()


func _on_presets(presets: Array, _id: int) -> void:
	for stream in PRESETS.keys():
		var menu: OptionButton = _menus[stream]
		while menu.get_item_count() > 1:
			menu.remove_item(1)
		for p in presets:
			if p["effect"] == PRESETS[stream]:
				menu.add_item(p["name"])


func _on_preset(index: int, stream: String) -> void:
	if index > 0:
		_client.preset_load(stream, _menus[stream].get_item_text(index))
		_menus[stream].select(0)


func _on_budget(index: int) -> void:
	_flame.max_particles = BUDGETS[index]


func _on_budget_refused(_stream: String, message: String) -> void:
	_status.text = "every particle: " + message


func _show_particles() -> void:
	var drawn: int = _flame.particles
	var whole: int = _flame.stream_particles
	_particles.text = "%d of %d particles (budget)" % [drawn, whole] if whole > drawn else "%d particles" % drawn


func _on_error(code: String, message: String, _param: String, _id: int, _stream: String) -> void:
	_status.text = "%s: %s" % [code, message]
