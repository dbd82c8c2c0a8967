// The character of a C++ frame (frame_reference.cpp, whose header comment says what a frame includes):
// the data `bench` hands the program, the simulation object, the query, the inertialization, the root
// motion, forward kinematics and foot locking with leg IK, shared by the MM and LMM frames; the
// database's pose and the decompressor's output as a pose.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "frame_pose.h"
#include "nnet_reference.h"

namespace {

enum TUNING { VEL_HL, ROT_HL, DEADZONE, RUN_FWD, RUN_SIDE, RUN_BACK, WALK_FWD, WALK_SIDE, WALK_BACK,
              INERT_HL, INTERVAL, FORCE_RATE, TRANSITION_COST, EXCLUDE_WINDOW, IDLE_DELAY, ADJ_POS_HL,
              ADJ_ROT_HL, ADJ_RATIO, CLAMP_DIST, CLAMP_ANGLE, UNLOCK_RADIUS, IK_BLEND_HL, FOOT_HEIGHT, N_TUNING };

struct Data {
    int J = 0, N = 0, D = 0, start = 0;
    std::vector<int32_t> parents, legs, stop, offsets, picks, slices;
    std::vector<float> pos, rot, vel, ang, X, mean, inv, bias, net_mean, net_inv, inputs, tun;
    std::vector<uint8_t> contacts, mask, idle;
    Net nets[3];   // decompressor, stepper, projector

    // feature i: raw from normalised, raw from the networks' space, raw to the networks' space
    float raw(int i, float x) const { return x / inv[size_t(i)] + mean[size_t(i)]; }
    float raw_of_net(int i, float x) const { return x / net_inv[size_t(i)] + net_mean[size_t(i)]; }
    float net_of_raw(int i, float x) const { return (x - net_mean[size_t(i)]) * net_inv[size_t(i)]; }
};

struct Character {
    const Data& d;
    V3 sim_pos, sim_vel, sim_acc, sim_ang, root_pos, prev_vel, lock[2], ik_off[2], ik_vel[2];
    Q sim_rot, root_rot, prev_rot;
    bool vel_high = false, rot_high = false, locked[2] = {false, false}, was_contact[2] = {false, false};
    bool needs_search = true;
    float since_search = 0, released = 0;
    Pose source, shown, target;
    Inertializer inert;
    std::vector<V3> gp, lp;
    std::vector<Q> gr, lr;
    std::vector<float> raw, query;
    int searches = 0, jumps = 0;

    explicit Character(const Data& data) : d(data) {
        for (Pose* p : {&source, &shown, &target, &inert.off}) p->resize(size_t(d.J));
        gp.resize(size_t(d.J)); lp.resize(size_t(d.J)); gr.resize(size_t(d.J)); lr.resize(size_t(d.J));
        raw.resize(size_t(d.D)); query.resize(size_t(d.D));
    }
    const float* tun() const { return d.tun.data(); }

    // input -> desired velocity and rotation, the forced-search test, the simulation's spring step
    bool simulate(const float* in, float dt, V3& dv, Q& dr) {
        const float* t = tun();
        auto stick = [&](float x, float y) {
            const float m = std::sqrt(x * x + y * y);
            const float k = m <= t[DEADZONE] ? 0.0f : std::min((m - t[DEADZONE]) / (1.0f - t[DEADZONE]), 1.0f) / m;
            return rotate(yaw(in[6]), V3{-x * k, 0, y * k});
        };
        const V3 left = stick(in[0], in[1]), right = stick(in[2], in[3]);
        released = length(left) > 0 ? 0.0f : released + dt;
        const bool walk = in[4] > 0.5f;
        const V3 l = inv_rotate(sim_rot, left);
        const float fwd = t[walk ? WALK_FWD : RUN_FWD], side = t[walk ? WALK_SIDE : RUN_SIDE];
        dv = rotate(sim_rot, V3{l.x * side, 0, l.z * (l.z > 0 ? fwd : t[walk ? WALK_BACK : RUN_BACK])});
        if (in[5] > 0.5f) dr = length(right) > 1e-5f ? yaw(std::atan2(right.x, right.z)) : yaw(in[6]);
        else dr = length(dv) > 1e-5f ? yaw(std::atan2(dv.x, dv.z)) : prev_rot;
        bool forced = false;
        const float vel_rate = length(dv - prev_vel) / dt;
        const float rot_rate = length(to_scaled_angle_axis(shortest(dr * conj(prev_rot)))) / dt;
        for (auto [rate, high] : {std::pair<float, bool*>{vel_rate, &vel_high}, {rot_rate, &rot_high}}) {
            if (rate > t[FORCE_RATE]) *high = true;
            else if (*high) { *high = false; forced = true; }
        }
        prev_vel = dv; prev_rot = dr;
        spring_character(sim_pos, sim_vel, sim_acc, dv, t[VEL_HL], dt);
        spring_rotation(sim_rot, sim_ang, dr, t[ROT_HL], dt);
        return forced;
    }

    // the query: `raw` holds the playing pose's raw features; the trajectory goes into it, then normalised
    void make_query(V3 dv, Q dr) {
        const float* t = tun();
        V3 traj_p[8], traj_d[8];
        for (size_t o = 0; o < d.offsets.size() && o < 8; ++o) {
            V3 p = sim_pos, v = sim_vel, a = sim_acc, w = sim_ang;
            Q r = sim_rot;
            const float dt = float(d.offsets[o]) / 60.0f;
            spring_character(p, v, a, dv, t[VEL_HL], dt);
            spring_rotation(r, w, dr, t[ROT_HL], dt);
            traj_p[o] = inv_rotate(root_rot, p - root_pos);
            traj_d[o] = inv_rotate(root_rot, rotate(r, V3{0, 0, 1}));
        }
        for (size_t k = 0; k < d.picks.size(); k += 4) {
            const V3 v = (d.picks[k + 1] ? traj_d : traj_p)[d.picks[k + 2]];
            raw[size_t(d.picks[k])] = d.picks[k + 3] ? v.z : v.x;
        }
        for (int k = 0; k < d.D; ++k) query[size_t(k)] = (raw[size_t(k)] - d.mean[size_t(k)]) * d.inv[size_t(k)];
    }

    // after the advance: offsets, root motion, forward kinematics, foot locking and leg IK
    void finish(float dt) {
        const float* t = tun();
        inert.update(shown, source, t[INERT_HL], dt);
        const V3 wv = rotate(root_rot, shown.v[0]), wa = rotate(root_rot, shown.a[0]);
        root_pos = root_pos + wv * dt;
        root_rot = normalize(from_scaled_angle_axis(wa * dt) * root_rot);
        const float fp = 1.0f - std::exp(-2 * half_damping(t[ADJ_POS_HL]) * dt);
        const float fr = 1.0f - std::exp(-2 * half_damping(t[ADJ_ROT_HL]) * dt);
        auto capped = [&](V3 v, V3 speed) {
            const float cap = t[ADJ_RATIO] * length(speed) * dt, n = length(v);
            return n > cap ? v * (cap / n) : v;
        };
        root_pos = root_pos + capped((sim_pos - root_pos) * fp, wv);
        const V3 towards = to_scaled_angle_axis(shortest(sim_rot * conj(root_rot))) * fr;
        root_rot = normalize(from_scaled_angle_axis(capped(towards, wa)) * root_rot);
        const V3 off = root_pos - sim_pos;
        if (length(off) > t[CLAMP_DIST]) root_pos = sim_pos + off * (t[CLAMP_DIST] / length(off));
        const V3 turn = to_scaled_angle_axis(shortest(root_rot * conj(sim_rot)));
        const float max_angle = t[CLAMP_ANGLE] * 3.14159265f / 180.0f;
        if (length(turn) > max_angle)
            root_rot = normalize(from_scaled_angle_axis(turn * (max_angle / length(turn))) * sim_rot);
        lp = shown.p; lr = shown.r;
        gp[0] = lp[0] = root_pos; gr[0] = lr[0] = root_rot;
        forward_kinematics(gp, gr, lp, lr, d.parents);
        for (int f = 0; f < 2; ++f) {
            const int* chain = d.legs.data() + 4 * f;
            const V3 toe = gp[size_t(chain[3])];
            const bool contact = shown.contact[f];
            if (contact && !was_contact[f]) {
                locked[f] = true;
                lock[f] = toe;
                lock[f].y = std::max(toe.y, t[FOOT_HEIGHT]);
            }
            if (locked[f] && (!contact || length(toe - lock[f]) > t[UNLOCK_RADIUS])) {
                locked[f] = false; ik_off[f] = lock[f] - toe; ik_vel[f] = V3{};
            }
            if (!locked[f]) decay(ik_off[f], ik_vel[f], t[IK_BLEND_HL], dt);
            was_contact[f] = contact;
            V3 goal = locked[f] ? lock[f] : toe + ik_off[f];
            goal.y = std::max(goal.y, t[FOOT_HEIGHT]);
            two_bone_ik(lr, gr, gp, chain, goal + (gp[size_t(chain[2])] - toe));
            forward_kinematics(gp, gr, lp, lr, d.parents, size_t(chain[0]));
            const size_t foot = size_t(chain[2]), knee = size_t(chain[1]);
            const Q look = between(gp[size_t(chain[3])] - gp[foot], goal - gp[foot]);
            lr[foot] = normalize(conj(gr[knee]) * (look * gr[foot]));
        }
        forward_kinematics(gp, gr, lp, lr, d.parents);
    }

    void reset() {
        sim_pos = sim_vel = sim_acc = sim_ang = root_pos = prev_vel = V3{};
        sim_rot = root_rot = prev_rot = Q{};
        vel_high = rot_high = locked[0] = locked[1] = was_contact[0] = was_contact[1] = false;
        ik_off[0] = ik_off[1] = ik_vel[0] = ik_vel[1] = V3{};
        needs_search = true; since_search = released = 0; searches = jumps = 0;
        for (size_t i = 0; i < size_t(d.J); ++i) {
            inert.off.p[i] = inert.off.v[i] = inert.off.a[i] = V3{};
            inert.off.r[i] = Q{};
        }
    }
    bool search_due(bool forced, bool must, float dt) {
        since_search += dt;
        if (!(needs_search || forced || must || since_search >= tun()[INTERVAL] - 1e-6f)) return false;
        needs_search = false; since_search = 0; ++searches;
        return true;
    }
};

void database_pose(const Data& d, int frame, Pose& p) {
    const size_t b = size_t(frame) * size_t(d.J);
    for (size_t i = 0; i < size_t(d.J); ++i) {
        const float *x = &d.pos[(b + i) * 3], *r = &d.rot[(b + i) * 4];
        const float *v = &d.vel[(b + i) * 3], *a = &d.ang[(b + i) * 3];
        p.p[i] = {x[0], x[1], x[2]}; p.r[i] = {r[0], r[1], r[2], r[3]};
        p.v[i] = {v[0], v[1], v[2]}; p.a[i] = {a[0], a[1], a[2]};
    }
    p.contact[0] = d.contacts[size_t(frame) * 2] != 0;
    p.contact[1] = d.contacts[size_t(frame) * 2 + 1] != 0;
}

// The decompressor's output vector y as a pose (2-axis rotations to quaternions by Gram-Schmidt).
void decode(const Data& d, const float* y, Pose& p) {
    const int* s = d.slices.data();
    p.p[0] = V3{}; p.r[0] = Q{};
    p.v[0] = {y[s[4]], y[s[4] + 1], y[s[4] + 2]};
    p.a[0] = {y[s[5]], y[s[5] + 1], y[s[5] + 2]};
    for (int i = 1; i < d.J; ++i) {
        const int j = i - 1;
        const float* m = y + s[1] + 6 * j;
        const V3 a = normalize(V3{m[0], m[2], m[4]});
        const V3 b0{m[1], m[3], m[5]};
        const V3 b = normalize(b0 - a * dot(a, b0));
        p.r[size_t(i)] = from_columns(a, b, cross(a, b));
        p.p[size_t(i)] = {y[s[0] + 3 * j], y[s[0] + 3 * j + 1], y[s[0] + 3 * j + 2]};
        p.v[size_t(i)] = {y[s[2] + 3 * j], y[s[2] + 3 * j + 1], y[s[2] + 3 * j + 2]};
        p.a[size_t(i)] = {y[s[3] + 3 * j], y[s[3] + 3 * j + 1], y[s[3] + 3 * j + 2]};
    }
    p.contact[0] = y[s[6]] > 0.5f;
    p.contact[1] = y[s[6] + 1] > 0.5f;
}

}  // namespace
