#version 330
// Screen-space thick lines: each instance is a segment, expanded to a quad of u_width_px pixels
// (with square caps so polyline corners have no gaps). Segments crossing the near plane are clipped
// in clip space. Vertices are pulled slightly towards the camera so lines lying on the ground win
// the depth test without visibly moving.
#include "frame.glsl"
uniform float u_width_px;
uniform float u_depth_pull;
in vec2 in_corner;   // x: 0 start / 1 end, y: -1 / +1 side
in vec3 i_p0;
in vec3 i_p1;
in vec4 i_c0;
in vec4 i_c1;
out vec4 v_color;
vec4 to_clip(vec3 p) {
    vec4 v = u_view * vec4(p, 1.0);
    v.xyz *= 1.0 - u_depth_pull;
    return u_proj * v;
}
void main() {
    vec4 c0 = to_clip(i_p0);
    vec4 c1 = to_clip(i_p1);
    float d0 = c0.z + c0.w;   // >= 0 in front of the near plane
    float d1 = c1.z + c1.w;
    if (d0 < 0.0 && d1 < 0.0) {
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);   // fully behind: outside the clip volume
        v_color = vec4(0.0);
        return;
    }
    if (d0 < 0.0) c0 = mix(c0, c1, d0 / (d0 - d1));
    if (d1 < 0.0) c1 = mix(c1, c0, d1 / (d1 - d0));
    vec2 s0 = c0.xy / c0.w * 0.5 * u_viewport;
    vec2 s1 = c1.xy / c1.w * 0.5 * u_viewport;
    vec2 dir = s1 - s0;
    float n = length(dir);
    dir = n > 1e-6 ? dir / n : vec2(1.0, 0.0);
    vec2 side = vec2(-dir.y, dir.x);
    vec4 c = in_corner.x < 0.5 ? c0 : c1;
    vec2 offset = 0.5 * u_width_px * (side * in_corner.y + dir * (in_corner.x * 2.0 - 1.0));
    c.xy += offset / (0.5 * u_viewport) * c.w;
    gl_Position = c;
    v_color = in_corner.x < 0.5 ? i_c0 : i_c1;
}
