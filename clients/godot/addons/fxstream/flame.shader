// flame.shader — FxFlame's particles: one MultiMesh instance per particle, placed from the
// frame's texture (PROTOCOL.md §7.8: texel i at (i % width, i / width) holds x, y, z - origin
// and T) as a camera-facing sprite, coloured like the web page's hdr mode (clients/web/src/
// flame.js): the chromaticity-normalised blackbody colour of T (digest 002 §4.2) times
// heat², heat = (T - T_amb) / (T_white - T_amb), added to the picture; soft round sprites
// (poly6 falloff). Cold particles (heat 0) are not drawn.
shader_type spatial;
render_mode unshaded, blend_add, depth_draw_never, cull_disabled, skip_vertex_transform, shadows_disabled;

uniform sampler2D particles;         // FxFrame.image, no filtering
uniform sampler2D blackbody;         // 800 K .. 3000 K left to right
uniform int width = 1024;
uniform vec3 origin;
uniform float size = 0.01;           // sprite diameter in stream units
uniform float t_ambient = 300.0;     // the stream's T_amb
uniform float t_white = 4000.0;      // the temperature drawn white (the table's 3000 K moved there)
uniform float gain = 0.08;
uniform float exposure = 1.0;

varying vec3 color;

void vertex() {
	vec4 p = texelFetch(particles, ivec2(INSTANCE_ID % width, INSTANCE_ID / width), 0);
	float heat = clamp((p.w - t_ambient) / max(t_white - t_ambient, 1.0), 0.0, 1.0);
	vec4 mv = MODELVIEW_MATRIX * vec4(origin + p.xyz, 1.0);
	float units = length(MODELVIEW_MATRIX[0].xyz); // the node's scale: stream units to the world's
	mv.xy += VERTEX.xy * size * units;
	VERTEX = heat > 0.0 ? mv.xyz : vec3(0.0);      // a cold particle collapses to a point: not drawn
	float t = (p.w * 3000.0 / t_white - 800.0) / 2200.0;
	color = texture(blackbody, vec2(clamp(t, 0.0, 1.0), 0.5)).rgb * heat * heat;
}

void fragment() {
	vec2 q = UV * 2.0 - 1.0;
	float s = max(1.0 - dot(q, q), 0.0);
	ALBEDO = color * gain * exposure * s * s * s;
}
