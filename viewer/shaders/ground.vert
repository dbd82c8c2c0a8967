#version 330
// The ground square, u_size wide around u_center (x, z) at height u_height.
#include "frame.glsl"
uniform vec2 u_center;
uniform float u_size;
uniform float u_height;
in vec2 in_xz;
out vec3 v_world;
void main() {
    v_world = vec3(u_center.x + in_xz.x * u_size, u_height, u_center.y + in_xz.y * u_size);
    gl_Position = u_view_proj * vec4(v_world, 1.0);
}
