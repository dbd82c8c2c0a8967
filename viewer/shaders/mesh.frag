#version 330
// Plain lighting of the instanced meshes (joints and bones drawn as sticks, arrows, markers).
#include "frame.glsl"
in vec3 v_normal;
in vec3 v_world;
in vec4 v_color;
out vec4 f_color;
void main() {
    vec3 n = normalize(v_normal);
    vec3 l = normalize(u_light_dir);
    vec3 to_eye = normalize(u_eye - v_world);
    float sky = 0.75 + 0.25 * n.y;                        // hemisphere ambient
    float diffuse = max(dot(n, l), 0.0);
    float fill = 0.2 * max(dot(n, to_eye), 0.0);          // keeps the shadow side readable
    float spec = pow(max(dot(n, normalize(l + to_eye)), 0.0), 32.0) * u_specular;
    vec3 rgb = v_color.rgb * (u_ambient * sky + u_diffuse * diffuse + fill) + vec3(spec);
    f_color = vec4(rgb, v_color.a);
}
