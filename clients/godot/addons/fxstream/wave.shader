// wave.shader — FxTexture's material: the energy wave's texture (PROTOCOL.md §7.8, one channel
// of raw energy B, or RGBA from the stream's own colour map) as emitted light. A one-channel
// texture is coloured through `ramp` (B 0 .. 1 left to right, HDR beyond) times `tint`;
// `energy` above 1 drives Godot's glow (WorldEnvironment glow on, HDR threshold below it).
// Additive: black adds nothing, so the quad needs no alpha.
shader_type spatial;
render_mode unshaded, blend_add, depth_draw_never, cull_disabled, shadows_disabled;

uniform sampler2D wave : hint_black;
uniform sampler2D ramp : hint_white;
uniform bool one_channel = true;
uniform vec4 tint : hint_color = vec4(1.0);
uniform float energy = 2.0;

void fragment() {
	vec4 t = texture(wave, UV);
	vec3 c = one_channel ? texture(ramp, vec2(clamp(t.r, 0.0, 1.0), 0.5)).rgb * max(t.r, 0.0) : t.rgb * t.a;
	ALBEDO = c * tint.rgb * energy;
}
