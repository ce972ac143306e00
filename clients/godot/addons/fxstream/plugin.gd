# plugin.gd — registers the add-on's nodes in the editor's "Create New Node" dialog. The nodes
# work without the plugin enabled too (add their scripts to nodes, or instance them in code).
tool
extends EditorPlugin

const ICON = preload("icon.png")
const TYPES = [
	["FxStreamClient", "Node", "fx_client.gd"],
	["FxFlame", "Spatial", "fx_flame.gd"],
	["FxTexture", "Spatial", "fx_texture.gd"],
	["FxLightRig", "Spatial", "fx_light_rig.gd"],
	["FxEye", "Spatial", "fx_eye.gd"],
]


func _enter_tree() -> void:
	for t in TYPES:
		add_custom_type(t[0], t[1], load("res://addons/fxstream/" + t[2]), ICON)


func _exit_tree() -> void:
	for t in TYPES:
		remove_custom_type(t[0])
