#version 330
// The studio lighting on the mesh's own (interpolated) normals.
#include "frame.glsl"
in vec3 v_normal;
in vec3 v_world;
in vec4 v_color;
in float v_height;
out vec4 f_color;
#include "shade.glsl"
void main() {
    f_color = vec4(shade(normalize(v_normal), normalize(u_eye - v_world), v_color.rgb), v_color.a);
}
