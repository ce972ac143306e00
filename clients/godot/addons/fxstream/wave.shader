// wave.shader — FxTexture's material: the energy wave's texture (PROTOCOL.md §7.8: one channel
// of raw energy B, HDR, or RGBA from the stream's own colour map) as emitted light, with the
// browser page's display map (clients/web/src/wave.js and gl.js, the same math):
//   levels   B' = gain · F · max(B/F − floor_k, 0)^contrast, at most 8, where F (floor_b) is the
//            median B on the texture's border, measured by FxTexture each frame;
//   colour   C = max((1 − B')·C_b, 0) + B'·C_e (Watanabe 2016 eq. 4.8 in HDR) with the stream's
//            color_background and color_energy; RGBA textures as sent, scaled by B'/A;
//   window   a superellipse over the quad's outer 30% that reaches 0 before its border, so
//            the quad's edge never shows;
//   tone map with tone_map on, the hue-preserving glow map: the strongest channel m goes
//            through 1 − e^(−m) and the others keep their ratio to it, so a colour never clips
//            channel by channel; only light far above the display's range turns white. Use
//            the Environment's Linear tone map then (its other maps clip or shift hues per
//            channel), with glow on and its HDR threshold under 1 for the halo. With tone_map
//            off the linear HDR colour goes to the Environment's own tone map and glow.
// Additive and unshaded, like the page: black adds nothing. With `billboard` the quad turns
// to face the camera (the page's toon scene does so), keeping the node's position and scale.
// GLES3 and GLES2.
shader_type spatial;
render_mode unshaded, blend_add, depth_draw_never, cull_disabled, shadows_disabled;

uniform sampler2D wave : hint_black;
uniform bool one_channel = true;
uniform vec3 color_energy = vec3(0.05, 0.35, 1.0);
uniform vec3 color_background = vec3(0.0);
uniform float floor_b = 1.0;
uniform float floor_k = 1.15;
uniform float gain = 1.5;
uniform float contrast = 2.0;
uniform float exposure = 1.0;
uniform bool tone_map = true;
uniform bool billboard = true;

void vertex() {
	if (billboard) {
		float s = length(WORLD_MATRIX[0].xyz);
		MODELVIEW_MATRIX = INV_CAMERA_MATRIX * mat4(CAMERA_MATRIX[0] * s, CAMERA_MATRIX[1] * s, CAMERA_MATRIX[2] * s, WORLD_MATRIX[3]);
	}
}

vec3 glow_tone(vec3 c) {
	float m = max(max(c.r, c.g), c.b);
	if (m <= 1e-6) {
		return vec3(0.0);
	}
	return (1.0 - exp(-m)) * mix(c / m, vec3(1.0), smoothstep(2.0, 10.0, m));
}

void fragment() {
	const float MAX_B = 8.0;     // white-hot already: more would only widen the glow
	const float WINDOW_N = 3.0;  // the window's superellipse exponent
	const float EDGE = 0.3;      // and its width, a share of the half-side
	vec4 t = texture(wave, UV);
	float raw = one_channel ? t.r : t.a;
	float b = min(gain * floor_b * pow(max(raw / floor_b - floor_k, 0.0), contrast), MAX_B);
	vec3 col = one_channel ? max((1.0 - b) * color_background, vec3(0.0)) + b * color_energy
			: t.rgb * min(b / max(t.a, 1e-3), 1.0);
	vec2 p = pow(abs(2.0 * UV - 1.0), vec2(WINDOW_N));
	col *= (1.0 - smoothstep(1.0 - EDGE, 0.98, pow(p.x + p.y, 1.0 / WINDOW_N))) * exposure;
	ALBEDO = tone_map ? glow_tone(col) : col;
}
