#version 330
// Instanced "oriented mesh": each instance is a segment a->b with a radius and a colour. Mesh
// vertices give radial offsets (x, z) and an axial offset (y) in radius units plus a parameter t
// along the segment, so one vertex format draws spheres (a == b), cylinders and cones.
#include "frame.glsl"
uniform float u_cone;  // 1 for meshes stretched along the axis (cone sides): fixes normals
in vec3 in_pos;
in float in_t;
in vec3 in_normal;
in vec3 i_a;
in vec3 i_b;
in float i_radius;
in vec4 i_color;
out vec3 v_normal;
out vec3 v_world;
out vec4 v_color;
void main() {
    vec3 d = i_b - i_a;
    float len = length(d);
    vec3 axis = len > 1e-9 ? d / len : vec3(0.0, 1.0, 0.0);
    vec3 helper = abs(axis.y) < 0.99 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0);
    vec3 u = normalize(cross(axis, helper));
    vec3 v = cross(u, axis);
    vec3 world = i_a + axis * (in_t * len + in_pos.y * i_radius)
               + i_radius * (in_pos.x * u + in_pos.z * v);
    vec3 n = in_normal;
    if (u_cone > 0.5) {
        // the cone is scaled by (r, len, r); normals take the inverse scale
        n = vec3(n.x * len, n.y * i_radius, n.z * len);
    }
    v_normal = n.x * u + n.y * axis + n.z * v;
    v_world = world;
    v_color = i_color;
    gl_Position = u_view_proj * vec4(world, 1.0);
}
