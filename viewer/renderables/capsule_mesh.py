"""Rounded cones ("capsules" whose two ends may differ in radius), drawn instanced, and their
planar ground shadow. GLSL sources and the unit mesh; the GL objects live in ``base.Resources``.

Each instance is a segment a -> b with a radius at each end. The mesh is two caps of latitude
rings plus the side between their rims: the vertex shader places cap vertices on the sphere at
``a`` (radius ``ra``) or ``b`` (radius ``rb``) and turns the rims so the side is tangent to both
spheres, which gives one smooth surface for any pair of radii. ``a == b`` with ``ra == rb`` is a
sphere, so joints, heads and bones share one draw call.
"""
from __future__ import annotations

import numpy as np

CAPSULE_INSTANCE_FLOATS = 12   # a(3) b(3) ra(1) rb(1) color(4)
CAPSULE_INFLATE = 1.09   # exact capsules: the 16 x 4 mesh scaled by this contains the surface (facets ~4 % deep)

CAPSULE_VS = """
#version 330
uniform mat4 u_view;
uniform mat4 u_proj;
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
"""

SHADE_GLSL = """
// Soft studio lighting: a slightly wrapped Lambert key light, a sky/ground hemisphere ambient, a
// little Blinn specular and a cool rim that separates the silhouette from the background.
vec3 shade(vec3 n, vec3 to_eye, vec3 color) {
    vec3 l = normalize(u_light_dir);
    float key = clamp((dot(n, l) + 0.25) / 1.25, 0.0, 1.0);
    float sky = 0.5 + 0.5 * n.y;
    vec3 ambient = mix(vec3(0.42, 0.38, 0.36), vec3(0.9, 0.95, 1.05), sky);
    float spec = pow(max(dot(n, normalize(l + to_eye)), 0.0), 48.0) * u_specular * 2.0;
    float rim = pow(1.0 - max(dot(n, to_eye), 0.0), 4.0) * 0.25 * sky;
    return color * (u_ambient * 0.9 * ambient + u_diffuse * 1.15 * key) + vec3(spec) + rim * vec3(0.7, 0.8, 1.0);
}
"""

# the lighting on the mesh's own (interpolated) normals
CAPSULE_FS = """
#version 330
uniform vec3 u_light_dir;   // towards the light, world space
uniform vec3 u_eye;
uniform float u_ambient;
uniform float u_diffuse;
uniform float u_specular;
in vec3 v_normal;
in vec3 v_world;
in vec4 v_color;
in float v_height;
out vec4 f_color;
SHADE_GLSL
void main() {
    f_color = vec4(shade(normalize(v_normal), normalize(u_eye - v_world), v_color.rgb), v_color.a);
}
"""

# The same lighting on the exact surface: each fragment of the (inflated) mesh casts its view ray
# at the rounded cone and writes the hit's depth, so bones meet along exact, smooth curves
# however coarse the mesh. Writing depth turns early depth tests off: cheap on a GPU, about
# 1.5x the frame time on software GL, where the plain mesh is used (see Resources).
CAPSULE_EXACT_FS = """
#version 330
#extension GL_ARB_conservative_depth : enable
#ifdef GL_ARB_conservative_depth
layout (depth_greater) out float gl_FragDepth;   // the bounding mesh lies in front: early depth test
#endif
uniform mat4 u_view;
uniform mat4 u_proj;
uniform vec3 u_light_dir;   // towards the light, world space
uniform vec3 u_eye;
uniform float u_ambient;
uniform float u_diffuse;
uniform float u_specular;
in vec3 v_normal;
in vec3 v_world;
in vec4 v_color;
in float v_height;
flat in vec3 v_a;
flat in vec3 v_b;
flat in vec2 v_r;
out vec4 f_color;
SHADE_GLSL
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
"""

CAPSULE_FS = CAPSULE_FS.replace("SHADE_GLSL", SHADE_GLSL)
CAPSULE_EXACT_FS = CAPSULE_EXACT_FS.replace("SHADE_GLSL", SHADE_GLSL)

SHADOW_DEPTH_PULL = 1e-3   # shadows: in front of the ground, behind lines on it (2e-3)

# Shadow resolve (pass 2 of base.draw_shadows): a ground rectangle over the shadows' bounds.
SHADOW_RESOLVE_VS = """
#version 330
uniform mat4 u_view;
uniform mat4 u_proj;
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
"""

SHADOW_RESOLVE_FS = """
#version 330
out vec4 f_color;
void main() { f_color = vec4(0.0, 0.0, 0.0, 1.0); }
"""

# Shadow passes (see base.draw_shadows): the first writes 1 - darkness into destination alpha with MIN
# blending (overlapping parts darken once), the second multiplies the colour by it and puts the
# alpha back to 1. Parts high above the ground cast a lighter shadow.
SHADOW_FS = """
#version 330
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
"""


def capsule_mesh(segments: int = 16, cap_rings: int = 4):
    """Vertices (ring cos, ring sin, lat, end) float32 and uint32 triangles of the unit rounded
    cone, counter-clockwise seen from outside."""
    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.c_[np.cos(phi), np.sin(phi)]
    lat = np.linspace(0.0, 1.0, cap_rings + 1)   # pole .. rim
    rows = []
    for end in (0.0, 1.0):
        for t in lat:
            rows.append(np.c_[ring, np.full(segments, t), np.full(segments, end)])
    verts = np.concatenate(rows).astype(np.float32)
    k = np.arange(segments)
    k1 = (k + 1) % segments
    tris = []
    n_rows = 2 * (cap_rings + 1)
    # rows in order: cap a pole..rim, cap b pole..rim; connect a's rows, a's rim to b's rim, b's rows
    order = list(range(cap_rings + 1)) + list(range(2 * cap_rings + 1, cap_rings, -1))
    for r0, r1 in zip(order[:-1], order[1:]):
        base0, base1 = r0 * segments, r1 * segments
        tris.append(np.c_[base0 + k, base0 + k1, base1 + k])
        tris.append(np.c_[base0 + k1, base1 + k1, base1 + k])
    tris = np.concatenate(tris)
    assert n_rows * segments == len(verts)
    return verts, _orient(verts, tris).astype(np.uint32)


def _reference_positions(verts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions and normals of the mesh for a = 0, b = +Y, ra = rb = 0.3 (same math as the shader)."""
    lat = np.where(verts[:, 3] < 0.5, -np.pi / 2 * (1 - verts[:, 2]), np.pi / 2 * (1 - verts[:, 2]))
    n = np.c_[np.cos(lat) * verts[:, 0], np.sin(lat), np.cos(lat) * verts[:, 1]]
    centre = np.c_[np.zeros(len(verts)), verts[:, 3], np.zeros(len(verts))]
    return centre + 0.3 * n, n


def _orient(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    p, n = _reference_positions(verts)
    a, b, c = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
    face = np.cross(b - a, c - a)
    flip = (face * (n[tris[:, 0]] + n[tris[:, 1]] + n[tris[:, 2]])).sum(axis=1) < 0
    tris = tris.copy()
    tris[flip] = tris[flip][:, ::-1]
    # degenerate triangles at the poles have no orientation and cover no pixels: drop them
    keep = np.linalg.norm(face, axis=1) > 1e-12
    return tris[keep]
