#version 330
// The same lighting on the exact surface: each fragment of the (inflated) mesh casts its view ray
// at the rounded cone and writes the hit's depth, so bones meet along exact, smooth curves
// however coarse the mesh. Writing depth turns early depth tests off: cheap on a GPU, about
// 1.5x the frame time on software GL, where the plain mesh is used (see base.Resources).
#extension GL_ARB_conservative_depth : enable
#ifdef GL_ARB_conservative_depth
layout (depth_greater) out float gl_FragDepth;   // the bounding mesh lies in front: early depth test
#endif
#include "frame.glsl"
in vec3 v_normal;
in vec3 v_world;
in vec4 v_color;
in float v_height;
flat in vec3 v_a;
flat in vec3 v_b;
flat in vec2 v_r;
out vec4 f_color;
#include "shade.glsl"
// nearest entry of the ray o + t d (|d| = 1) into a sphere, or 1e30
float hit_sphere(vec3 o, vec3 d, vec3 c, float r) {
    vec3 oc = o - c;
    float b = dot(oc, d);
    float h = b * b - dot(oc, oc) + r * r;
    return h < 0.0 ? 1e30 : -b - sqrt(h);
}

void main() {
    // The rounded cone is the convex hull of two spheres: its first hit is the nearest of the two
    // spheres' and the lateral cone's between its tangent circles. With q = p - a, y = q.w and
    // s = sin(alpha), c = cos(alpha), the lateral surface is |q|^2 c^2 - y^2 + 2 ra s y - ra^2 = 0.
    vec3 o = u_eye;
    vec3 d = normalize(v_world - u_eye);
    float ra = v_r.x, rb = v_r.y;
    vec3 ab = v_b - v_a;
    float len = length(ab);
    float t = min(hit_sphere(o, d, v_a, ra), hit_sphere(o, d, v_b, rb));
    vec3 n = vec3(0.0);
    bool side = false;
    if (len > 1e-9 && abs(ra - rb) < 0.97 * len) {
        vec3 w = ab / len;
        float s = (ra - rb) / len;
        float c2 = 1.0 - s * s;
        vec3 oa = o - v_a;
        float y0 = dot(oa, w), yd = dot(d, w);
        float A = c2 - yd * yd;
        float B = c2 * dot(oa, d) - y0 * yd + ra * s * yd;
        float C = c2 * dot(oa, oa) - y0 * y0 + 2.0 * ra * s * y0 - ra * ra;
        float h = B * B - A * C;
        if (h >= 0.0 && abs(A) > 1e-9) {
            float sq = sqrt(h);
            float t0 = (-B - sq) / A, t1 = (-B + sq) / A;
            for (int k = 0; k < 2; k++) {
                float tk = k == 0 ? min(t0, t1) : max(t0, t1);
                float y = y0 + tk * yd;
                if (tk > 0.0 && tk < t && y >= ra * s && y <= len + rb * s && ra - y * s >= 0.0) {
                    vec3 q = oa + tk * d;
                    vec3 radial = normalize(q - y * w);
                    n = sqrt(c2) * radial + s * w;
                    t = tk;
                    side = true;
                    break;
                }
            }
        }
    }
    if (t >= 1e29) discard;
    vec3 p = o + t * d;
    if (!side) n = distance(p, v_a) - ra < distance(p, v_b) - rb ? (p - v_a) / ra : (p - v_b) / rb;
    vec4 clip = u_proj * (u_view * vec4(p, 1.0));
    gl_FragDepth = 0.5 * clip.z / clip.w + 0.5;

    f_color = vec4(shade(normalize(n), -d, v_color.rgb), v_color.a);
}
