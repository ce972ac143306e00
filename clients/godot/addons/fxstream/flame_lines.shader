// flame_lines.shader — FxFlame's velocity lines (digest 002 §4.4): per particle a segment from
// its position to position + velocity_scale · velocity, read from the frame's second layer
// (PROTOCOL.md §7.8: the texel `rows` rows below the particle's), in the particle's blackbody
// colour fading to the tip, fainter for cooler particles, added to the picture.
shader_type spatial;
render_mode unshaded, blend_add, depth_draw_never, cull_disabled, skip_vertex_transform, shadows_disabled;

uniform sampler2D particles;
uniform sampler2D blackbody;
uniform int width = 1024;
uniform int rows = 1;
uniform vec3 origin;
uniform float velocity_scale = 0.005; // seconds: a line shows this much of the particle's path
uniform float t_ambient = 300.0;
uniform float t_white = 4000.0;
uniform float alpha = 0.3;

varying vec3 color;

void vertex() {
	ivec2 at = ivec2(INSTANCE_ID % width, INSTANCE_ID / width);
	vec4 p = texelFetch(particles, at, 0);
	vec4 v = texelFetch(particles, at + ivec2(0, rows), 0);
	float end = VERTEX.x; // the line mesh's vertices are x = 0 (the particle) and x = 1 (the tip)
	float heat = clamp((p.w - t_ambient) / max(t_white - t_ambient, 1.0), 0.0, 1.0);
	VERTEX = (MODELVIEW_MATRIX * vec4(origin + p.xyz + end * velocity_scale * v.xyz, 1.0)).xyz;
	float t = (p.w * 3000.0 / t_white - 800.0) / 2200.0;
	color = texture(blackbody, vec2(clamp(t, 0.0, 1.0), 0.5)).rgb * alpha * (0.35 + 0.65 * heat) * (1.0 - 0.8 * end);
}

void fragment() {
	ALBEDO = color;
}
