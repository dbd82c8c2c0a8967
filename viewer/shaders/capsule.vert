#version 330
// Rounded cones ("capsules" whose two ends may differ in radius), instanced: each instance is a
// segment a -> b with a radius at each end. Cap vertices go on the sphere at a (radius ra) or b
// (radius rb); the rims turn so the side is tangent to both spheres. The same vertex stage
// flattens them onto the ground along the light for the shadow pass (u_shadow).
#include "frame.glsl"
uniform float u_shadow;         // 1: flatten onto the ground plane along the light (shadow pass)
uniform vec3 u_shadow_dir;      // towards the light, normalised, y > 0
uniform float u_ground;         // ground height
uniform float u_depth_pull;     // shadow pass: fraction of view distance pulled towards the eye
uniform float u_inflate;        // lit pass: the mesh is a bound a little outside the exact surface
in vec2 in_ring;                // (cos, sin) of the angle around the axis
in float in_lat;                // 0 at the cap's pole .. 1 at its rim
in float in_end;                // 0: cap at a, 1: cap at b
in vec3 i_a;
in vec3 i_b;
in float i_ra;
in float i_rb;
in vec4 i_color;
out vec3 v_normal;
out vec3 v_world;
out vec4 v_color;
out float v_height;
flat out vec3 v_a;
flat out vec3 v_b;
flat out vec2 v_r;
void main() {
    v_a = i_a;
    v_b = i_b;
    v_r = vec2(i_ra, i_rb);
    vec3 d = i_b - i_a;
    float len = length(d);
    vec3 axis = len > 1e-9 ? d / len : vec3(0.0, 1.0, 0.0);
    // one fixed helper (a direction few bones point along) turns the rings of nearly parallel
    // bones alike, so their facets line up where they meet instead of poking through each other
    const vec3 HELPER = vec3(0.36, 0.48, 0.8);
    vec3 helper = abs(dot(axis, HELPER)) < 0.999 ? HELPER : vec3(1.0, 0.0, 0.0);
    vec3 u = normalize(cross(axis, helper));
    vec3 v = cross(u, axis);
    // the side leans by alpha so it touches both spheres: sin(alpha) = (ra - rb) / len
    float s = len > 1e-9 ? clamp((i_ra - i_rb) / len, -0.97, 0.97) : 0.0;
    float alpha = asin(s);
    const float HALF_PI = 1.5707963;
    float lat = in_end < 0.5 ? mix(-HALF_PI, alpha, in_lat) : mix(HALF_PI, alpha, in_lat);
    vec3 n = cos(lat) * (in_ring.x * u + in_ring.y * v) + sin(lat) * axis;
    float inflate = u_shadow > 0.5 ? 1.0 : u_inflate;
    vec3 world = in_end < 0.5 ? i_a + inflate * i_ra * n : i_b + inflate * i_rb * n;
    v_normal = n;
    v_color = i_color;
    v_height = world.y - u_ground;
    if (u_shadow > 0.5) {
        world -= u_shadow_dir * (max(v_height, 0.0) / u_shadow_dir.y);
        vec4 view_pos = u_view * vec4(world, 1.0);
        view_pos.xyz *= 1.0 - u_depth_pull;   // wins against the ground, loses against lines on it
        v_world = world;
        gl_Position = u_proj * view_pos;
        return;
    }
    v_world = world;
    gl_Position = u_proj * (u_view * vec4(world, 1.0));
}
