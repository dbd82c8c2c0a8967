#version 330
// Shadow pass 2 (see base.draw_shadows): a ground rectangle over the shadows' bounds.
#include "frame.glsl"
uniform vec4 u_rect;          // x0, z0, x1, z1 on the ground
uniform float u_ground;
uniform float u_depth_pull;
in vec2 in_corner;
void main() {
    vec3 world = vec3(mix(u_rect.x, u_rect.z, in_corner.x), u_ground, mix(u_rect.y, u_rect.w, in_corner.y));
    vec4 view_pos = u_view * vec4(world, 1.0);
    view_pos.xyz *= 1.0 - u_depth_pull;
    gl_Position = u_proj * view_pos;
}
