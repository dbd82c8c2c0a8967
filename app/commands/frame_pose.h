// The character pipeline of a C++ frame (frame_reference.cpp): 3-vectors and quaternions (w, x, y, z;
// Y up, forward +Z), the critically damped springs of the simulation object and of the inertialization
// offsets, forward kinematics and two-bone leg IK. Written for `lmm-studio bench` after the formulas the
// paper and the reference demo describe (../shared/notes/reference.md); floats throughout, as the demo.
#pragma once

#include <cmath>
#include <vector>

namespace {

struct V3 { float x = 0, y = 0, z = 0; };
struct Q { float w = 1, x = 0, y = 0, z = 0; };

inline V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline V3 operator-(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline V3 operator*(V3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
inline V3 operator/(V3 a, float s) { return {a.x / s, a.y / s, a.z / s}; }
inline float dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline float length(V3 a) { return std::sqrt(dot(a, a)); }
inline V3 cross(V3 a, V3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
inline V3 normalize(V3 a) { return a / (length(a) + 1e-8f); }

inline Q operator*(Q a, Q b) {
    return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
            a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}
inline Q conj(Q q) { return {q.w, -q.x, -q.y, -q.z}; }
inline Q normalize(Q q) {
    const float n = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z) + 1e-8f;
    return {q.w / n, q.x / n, q.y / n, q.z / n};
}
inline Q shortest(Q q) { return q.w < 0 ? Q{-q.w, -q.x, -q.y, -q.z} : q; }
inline V3 rotate(Q q, V3 v) {                      // q v q*
    const V3 u{q.x, q.y, q.z};
    const V3 t = cross(u, v) * 2.0f;
    return v + t * q.w + cross(u, t);
}
inline V3 inv_rotate(Q q, V3 v) { return rotate(conj(q), v); }
inline Q yaw(float angle) { return {std::cos(0.5f * angle), 0, std::sin(0.5f * angle), 0}; }
inline Q from_scaled_angle_axis(V3 v) {            // exp(v / 2)
    const float half = 0.5f * length(v);
    if (half < 1e-8f) return normalize(Q{1, 0.5f * v.x, 0.5f * v.y, 0.5f * v.z});
    const float s = std::sin(half) / (2.0f * half);
    return {std::cos(half), v.x * s, v.y * s, v.z * s};
}
inline V3 to_scaled_angle_axis(Q q) {              // 2 log(q)
    const float s = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
    if (s < 1e-8f) return {2 * q.x, 2 * q.y, 2 * q.z};
    const float k = 2.0f * std::atan2(s, q.w) / s;
    return {q.x * k, q.y * k, q.z * k};
}
inline Q between(V3 a, V3 b) {                     // the rotation taking direction a to direction b
    const V3 c = cross(a, b);
    return normalize(Q{std::sqrt(dot(a, a) * dot(b, b)) + dot(a, b), c.x, c.y, c.z});
}
// rotation matrix columns a, b, c -> quaternion
inline Q from_columns(V3 a, V3 b, V3 c) {
    const float tr = a.x + b.y + c.z;
    Q q;
    if (tr > 0) {
        const float s = std::sqrt(tr + 1.0f) * 2;
        q = {0.25f * s, (b.z - c.y) / s, (c.x - a.z) / s, (a.y - b.x) / s};
    } else if (a.x > b.y && a.x > c.z) {
        const float s = std::sqrt(1.0f + a.x - b.y - c.z) * 2;
        q = {(b.z - c.y) / s, 0.25f * s, (b.x + a.y) / s, (c.x + a.z) / s};
    } else if (b.y > c.z) {
        const float s = std::sqrt(1.0f + b.y - a.x - c.z) * 2;
        q = {(c.x - a.z) / s, (b.x + a.y) / s, 0.25f * s, (c.y + b.z) / s};
    } else {
        const float s = std::sqrt(1.0f + c.z - a.x - b.y) * 2;
        q = {(a.y - b.x) / s, (c.x + a.z) / s, (c.y + b.z) / s, 0.25f * s};
    }
    return normalize(q);
}

inline float half_damping(float halflife) { return 0.5f * 4.0f * 0.69314718f / (halflife + 1e-5f); }

// Critically damped spring of the simulation position towards a desired velocity, exact over dt.
inline void spring_character(V3& pos, V3& vel, V3& acc, V3 goal, float halflife, float dt) {
    const float y = half_damping(halflife), e = std::exp(-y * dt);
    const V3 j0 = vel - goal, j1 = acc + j0 * y;
    pos = (j1 * -1.0f / (y * y) + (j0 * -1.0f - j1 * dt) / y) * e + j1 / (y * y) + j0 / y + goal * dt + pos;
    vel = (j0 + j1 * dt) * e + goal;
    acc = (acc - j1 * (y * dt)) * e;
}
inline void spring_rotation(Q& rot, V3& ang, Q goal, float halflife, float dt) {
    const float y = half_damping(halflife), e = std::exp(-y * dt);
    const V3 j0 = to_scaled_angle_axis(shortest(rot * conj(goal))), j1 = ang + j0 * y;
    rot = normalize(from_scaled_angle_axis((j0 + j1 * dt) * e) * goal);
    ang = (ang - j1 * (y * dt)) * e;
}
// An offset decaying to zero on a critically damped spring (inertialization), exact over dt.
inline void decay(V3& x, V3& v, float halflife, float dt) {
    const float y = half_damping(halflife), e = std::exp(-y * dt);
    const V3 j1 = v + x * y;
    x = (x + j1 * dt) * e;
    v = (v - j1 * (y * dt)) * e;
}

// One pose, local to each bone's parent (bone 0: the root; its velocities in the root's own frame).
struct Pose {
    std::vector<V3> p, v, a;
    std::vector<Q> r;
    bool contact[2] = {false, false};
    void resize(size_t n) { p.resize(n); v.resize(n); a.resize(n); r.resize(n); }
};

// Inertialization: per bone offsets from the pose on screen to a transition's target, decayed every frame.
struct Inertializer {
    Pose off;
    void transition(const Pose& shown, const Pose& target) {
        for (size_t i = 0; i < shown.p.size(); ++i) {
            off.p[i] = shown.p[i] - target.p[i];
            off.v[i] = shown.v[i] - target.v[i];
            off.r[i] = shortest(shown.r[i] * conj(target.r[i]));
            off.a[i] = shown.a[i] - target.a[i];
        }
    }
    void update(Pose& out, const Pose& in, float halflife, float dt) {
        for (size_t i = 0; i < in.p.size(); ++i) {
            decay(off.p[i], off.v[i], halflife, dt);
            V3 r = to_scaled_angle_axis(off.r[i]);
            decay(r, off.a[i], halflife, dt);
            off.r[i] = from_scaled_angle_axis(r);
            out.p[i] = in.p[i] + off.p[i];
            out.v[i] = in.v[i] + off.v[i];
            out.r[i] = normalize(off.r[i] * in.r[i]);
            out.a[i] = in.a[i] + off.a[i];
        }
        out.contact[0] = in.contact[0];
        out.contact[1] = in.contact[1];
    }
};

inline void forward_kinematics(std::vector<V3>& gp, std::vector<Q>& gr, const std::vector<V3>& lp,
                               const std::vector<Q>& lr, const std::vector<int>& parents, size_t from = 1) {
    for (size_t i = from; i < lp.size(); ++i) {
        const int p = parents[i];
        gr[i] = gr[size_t(p)] * lr[i];
        gp[i] = gp[size_t(p)] + rotate(gr[size_t(p)], lp[i]);
    }
}

// Two-bone IK: turn the hip and knee (local rotations lr, globals gr/gp) so the foot reaches `target`.
inline void two_bone_ik(std::vector<Q>& lr, const std::vector<Q>& gr, const std::vector<V3>& gp,
                        const int* chain, V3 target) {
    const size_t hip = size_t(chain[0]), knee = size_t(chain[1]), foot = size_t(chain[2]);
    const V3 a = gp[hip], b = gp[knee], c = gp[foot];
    const float lab = length(b - a), lcb = length(b - c);
    const float lat = std::fmax(1e-4f, std::fmin(length(target - a), (lab + lcb) * 0.9999f));
    auto angle = [](float x) { return std::acos(std::fmax(-1.0f, std::fmin(1.0f, x))); };
    const float ac_ab0 = angle(dot(normalize(c - a), normalize(b - a)));
    const float ba_bc0 = angle(dot(normalize(a - b), normalize(c - b)));
    const float ac_at0 = angle(dot(normalize(c - a), normalize(target - a)));
    const float ac_ab1 = angle((lcb * lcb - lab * lab - lat * lat) / (-2.0f * lab * lat));
    const float ba_bc1 = angle((lat * lat - lab * lab - lcb * lcb) / (-2.0f * lab * lcb));
    const V3 bend = normalize(cross(c - a, rotate(gr[knee], V3{0, 0, 1})));
    const V3 turn = normalize(cross(c - a, target - a));
    const Q ga = gr[hip], gb = gr[knee];
    const Q r0 = from_scaled_angle_axis(inv_rotate(ga, bend) * (ac_ab1 - ac_ab0));
    const Q r1 = from_scaled_angle_axis(inv_rotate(gb, bend) * (ba_bc1 - ba_bc0));
    const Q r2 = from_scaled_angle_axis(inv_rotate(ga, turn) * ac_at0);
    lr[hip] = lr[hip] * (r0 * r2);
    lr[knee] = lr[knee] * r1;
}

}  // namespace
