#version 330
// Shadow pass 1 (see base.draw_shadows), after capsule.vert flattened the casters: writes
// 1 - darkness into destination alpha with MIN blending, so overlapping parts darken once. Parts
// high above the ground cast a lighter shadow.
uniform float u_strength;
uniform float u_fade_height;
in vec3 v_normal;
in vec3 v_world;
in vec4 v_color;
in float v_height;
out vec4 f_color;
void main() {
    float fade = 1.0 - 0.35 * clamp(v_height / u_fade_height, 0.0, 1.0);
    float dark = u_strength * v_color.a * fade;
    f_color = vec4(0.0, 0.0, 0.0, 1.0 - dark);
}
