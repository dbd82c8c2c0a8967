// Whole frames of motion matching (MM) and learned motion matching (LMM) in C++, for `lmm-studio bench`
// (issue 38): the per-frame work of the reference demo's update loop, on our database, features,
// networks, tuning and inputs, built with the demo's flags (cpp_reference.FLAGS), timed frame by frame.
//
// What one C++ frame includes, in order (both controllers):
//   input -> desired velocity and facing (camera-relative stick, deadzone, walk/run speeds per direction),
//   the forced-search test (rate of change of the desired motion), the simulation object's spring step;
//   when a search is due (every search interval, a forced search, MM at the end of a range): the
//   trajectory predicted at the feature offsets and the query (pose channels of the playing pose, the
//   trajectory in the character root's space, normalised), then
//     MM:  an exact search of every candidate frame, pruned by axis-aligned boxes over blocks of 64 and 16
//          frames (the demo's and the paper's acceleration), with the playing frame's exclusion window,
//          the range ends, the tag biases and the idle set once the stick has rested; a jump reads the
//          target pose from the database,
//     LMM: the projector on the query, the projected and playing features' costs against it; a jump
//          runs the decompressor on the projected state;
//   and a jump starts an inertialization (per-bone offsets); then the advance (MM: the next database
//   frame and its pose; LMM: the stepper, the state integrated over dt, the whole decompressor, its
//   output decoded: 2-axis rotations to quaternions), the offsets decayed and added to every bone,
//   the root integrated from the shown root velocities, adjustment and clamping towards the simulation
//   object, forward kinematics of every bone, foot locking (lock, unlock radius, blend back) with
//   two-bone IK and a toe look-at per leg, and forward kinematics again.
// Not included (ours does them, the demo does not): ground calibration, the root-shift counter-adjustment
// of planted feet, swing-foot clearance, LMM's idle set (the C++ projects where ours searches the idle
// frames), LMM's exact search for the database frame nearest each projection (ours finds the matched
// frame for the debugger and the metrics), the debug snapshot, pose packing to arrays. Nothing is drawn.
//
// Input file (little-endian), written by app/commands/bench_frame_reference.py: "LMMFR1"; int32 J,
// parents (J), leg chains (2 x hip knee foot toe); int32 N, D; float32 local positions (N x J x 3),
// rotations (N x J x 4), velocities, angular velocities (N x J x 3; bone 0: zero position, identity,
// root velocities in the root's frame); uint8 contacts (N x 2); float32 normalised features (N x D),
// mean, inverse scale (D each), per-frame bias (N); uint8 candidate and idle-set masks (N each); int32
// per-frame range stop (N); int32 T, trajectory offsets in frames (T); int32 K, query picks (K x: dim,
// 0 position | 1 direction, offset index, 0 x | 2 z); float32 networks' feature mean, inverse scale (D
// each); int32 pose-vector starts (positions, rotations, velocities, angular velocities, root velocity,
// root angular velocity, contacts); int32 start frame; 3 network blocks (nnet_reference.h:
// decompressor, stepper, projector); int32 ticks, float32 inputs (ticks x: left x, y, right x, y, walk,
// strafe, camera azimuth); int32 count, float32 tuning (TUNING below, in that order).
// Usage: frame_reference FILE ROUNDS. Output: one JSON object on stdout; per round and controller the
// median and mean frame time (us) over the ticks, the median over the ticks that searched, searches and
// jumps, and checks `bench` verifies (the
// first queries with the frames the search chose, the start state's decoded rotations).
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "frame_character.h"

namespace {

bool read_data(const char* path, Data& d) {
    FILE* f = std::fopen(path, "rb");
    if (!f) return false;
    Reader r{f};
    char magic[6] = {0};
    r.ok = std::fread(magic, 1, 6, f) == 6 && std::memcmp(magic, "LMMFR1", 6) == 0;
    d.J = r.i32();
    d.parents = r.ints(d.J);
    d.legs = r.ints(8);
    d.N = r.i32();
    d.D = r.i32();
    const int64_t nj = int64_t(d.N) * d.J;
    d.pos = r.floats(nj * 3); d.rot = r.floats(nj * 4); d.vel = r.floats(nj * 3); d.ang = r.floats(nj * 3);
    d.contacts = r.bytes(int64_t(d.N) * 2);
    d.X = r.floats(int64_t(d.N) * d.D); d.mean = r.floats(d.D); d.inv = r.floats(d.D); d.bias = r.floats(d.N);
    d.mask = r.bytes(d.N); d.idle = r.bytes(d.N); d.stop = r.ints(d.N);
    d.offsets = r.ints(r.i32());
    d.picks = r.ints(int64_t(r.i32()) * 4);
    d.net_mean = r.floats(d.D); d.net_inv = r.floats(d.D);
    d.slices = r.ints(7);
    d.start = r.i32();
    for (Net& n : d.nets) r.ok = r.ok && read_net(r, n);
    d.inputs = r.floats(int64_t(r.i32()) * 7);
    d.tun = r.floats(r.i32());
    std::fclose(f);
    bool ok = r.ok && d.J > 2 && d.N > 0 && d.D > 0 && d.tun.size() == N_TUNING && d.start >= 0 && d.start < d.N;
    for (int i = 1; ok && i < d.J; ++i) ok = d.parents[0] < 0 && d.parents[size_t(i)] >= 0 && d.parents[size_t(i)] < i;
    for (size_t k = 0; ok && k < d.picks.size(); k += 4)
        ok = d.picks[k] >= 0 && d.picks[k] < d.D && size_t(d.picks[k + 2]) < d.offsets.size();
    return ok && d.nets[0].n_in == d.nets[1].n_in && d.nets[2].n_in == d.D && d.nets[2].n_out == d.nets[1].n_in;
}

// Axis-aligned boxes over blocks of `size` consecutive frames of the normalised features.
struct Boxes {
    int size = 0;
    std::vector<float> lo, hi, bias;   // per block: D lows, D highs, the least bias
    void build(const Data& d, int block) {
        size = block;
        const int n = (d.N + block - 1) / block;
        lo.assign(size_t(n) * d.D, 1e30f); hi.assign(size_t(n) * d.D, -1e30f); bias.assign(size_t(n), 1e30f);
        for (int i = 0; i < d.N; ++i) {
            const size_t b = size_t(i / block);
            bias[b] = std::min(bias[b], d.bias[size_t(i)]);
            for (int k = 0; k < d.D; ++k) {
                const float x = d.X[size_t(i) * d.D + k];
                lo[b * d.D + k] = std::min(lo[b * d.D + k], x);
                hi[b * d.D + k] = std::max(hi[b * d.D + k], x);
            }
        }
    }
    // false when no frame of block b can cost less than `best` (early out per dimension)
    bool may_beat(size_t b, const float* q, int D, float base, float best) const {
        float cost = base + bias[b];
        for (int k = 0; k < D; ++k) {
            const float c = std::min(std::max(q[k], lo[b * D + k]), hi[b * D + k]) - q[k];
            cost += c * c;
            if (cost >= best) return false;
        }
        return true;
    }
};

// The exact best frame for query q (lmm/search.py's rules): the playing frame `cur` competes without the
// transition cost unless masked; other frames within the exclusion window of it do not compete.
int search(const Data& d, const Boxes& large, const Boxes& small, const float* q, int cur, bool idle_set) {
    const uint8_t* mask = idle_set ? d.idle.data() : d.mask.data();
    const int D = d.D, window = int(d.tun[EXCLUDE_WINDOW]);
    const float tc = d.tun[TRANSITION_COST];
    int best_i = cur;
    float best = 3.4e38f;
    if (mask[cur]) {
        best = d.bias[size_t(cur)];
        for (int k = 0; k < D; ++k) best += (q[k] - d.X[size_t(cur) * D + k]) * (q[k] - d.X[size_t(cur) * D + k]);
    }
    for (int L = 0; L < d.N; L += large.size) {
        if (!large.may_beat(size_t(L / large.size), q, D, tc, best)) continue;
        for (int S = L; S < std::min(L + large.size, d.N); S += small.size) {
            if (!small.may_beat(size_t(S / small.size), q, D, tc, best)) continue;
            for (int i = S; i < std::min(S + small.size, d.N); ++i) {
                if (!mask[i] || std::abs(i - cur) <= window) continue;
                float cost = tc + d.bias[size_t(i)];
                const float* x = d.X.data() + size_t(i) * D;
                for (int k = 0; k < D && cost < best; ++k) cost += (q[k] - x[k]) * (q[k] - x[k]);
                if (cost < best) { best = cost; best_i = i; }
            }
        }
    }
    return best_i;
}

using Clock = std::chrono::steady_clock;

struct Pass { double median_us, mean_us, searching_us; int searches, jumps; };

double median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
    return v[v.size() / 2];
}

// a pass's figures from its per-tick times (`searched`: the times of the ticks that searched)
Pass summarize(const std::vector<double>& us, const std::vector<double>& searched, const Character& c) {
    double sum = 0;
    for (double u : us) sum += u;
    return {median(us), sum / double(us.size()), median(searched), c.searches, c.jumps};
}

// One pass of motion matching over every input tick; `checks` (when given) gets the first queries and picks.
Pass run_mm(const Data& d, const Boxes& large, const Boxes& small, std::string* checks) {
    Character c(d);
    c.reset();
    int frame = d.start;
    database_pose(d, frame, c.shown);
    const float dt = 1.0f / 60.0f;
    const size_t ticks = d.inputs.size() / 7;
    std::vector<double> us(ticks), searched;
    for (size_t k = 0; k < ticks; ++k) {
        const auto t0 = Clock::now();
        const int before = c.searches;
        V3 dv; Q dr;
        const bool forced = c.simulate(&d.inputs[k * 7], dt, dv, dr);
        if (c.search_due(forced, frame >= d.stop[size_t(frame)] - 1, dt)) {
            for (int i = 0; i < d.D; ++i) c.raw[size_t(i)] = d.raw(i, d.X[size_t(frame) * d.D + i]);
            c.make_query(dv, dr);
            const bool idle = c.released >= d.tun[IDLE_DELAY] - 1e-6f;
            const int best = search(d, large, small, c.query.data(), frame, idle);
            if (checks && c.searches <= 3) {
                *checks += std::string(checks->empty() ? "" : ", ") + "{\"current\": " + std::to_string(frame) +
                           ", \"idle\": " + (idle ? "true" : "false") + ", \"best\": " + std::to_string(best) +
                           ", \"query\": [";
                for (int i = 0; i < d.D; ++i) {
                    char b[32];
                    std::snprintf(b, sizeof b, "%s%.9g", i ? ", " : "", double(c.query[size_t(i)]));
                    *checks += b;
                }
                *checks += "]}";
            }
            if (best != frame) {
                frame = best;
                ++c.jumps;
                database_pose(d, frame, c.target);
                c.inert.transition(c.shown, c.target);
            }
        }
        frame = std::min(frame + 1, d.stop[size_t(frame)] - 1);
        database_pose(d, frame, c.source);
        c.finish(dt);
        us[k] = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
        if (c.searches != before) searched.push_back(us[k]);
    }
    return summarize(us, searched, c);
}

// One pass of learned motion matching over every input tick.
Pass run_lmm(Data& d, std::vector<float>& start_state) {
    Net &dec = d.nets[0], &step = d.nets[1], &proj = d.nets[2];
    Character c(d);
    c.reset();
    const int S = step.n_in, D = d.D;
    std::vector<float> state = start_state, deriv(size_t(S), 0.0f), projected(size_t(S), 0.0f);
    std::vector<float> y(size_t(dec.n_out), 0.0f), in(size_t(D), 0.0f);
    evaluate(dec, state.data(), y.data());
    decode(d, y.data(), c.shown);
    const float dt = 1.0f / 60.0f;
    const size_t ticks = d.inputs.size() / 7;
    std::vector<double> us(ticks), searched;
    auto cost = [&](const float* s) {     // network-space features -> the query's cost
        float sum = 0;
        for (int i = 0; i < D; ++i) {
            const float x = (d.raw_of_net(i, s[i]) - d.mean[size_t(i)]) * d.inv[size_t(i)] - c.query[size_t(i)];
            sum += x * x;
        }
        return sum;
    };
    for (size_t k = 0; k < ticks; ++k) {
        const auto t0 = Clock::now();
        const int before = c.searches;
        V3 dv; Q dr;
        const bool forced = c.simulate(&d.inputs[k * 7], dt, dv, dr);
        if (c.search_due(forced, false, dt)) {
            for (int i = 0; i < D; ++i) c.raw[size_t(i)] = d.raw_of_net(i, state[size_t(i)]);
            c.make_query(dv, dr);
            for (int i = 0; i < D; ++i) in[size_t(i)] = d.net_of_raw(i, c.raw[size_t(i)]);
            evaluate(proj, in.data(), projected.data());
            if (cost(projected.data()) + d.tun[TRANSITION_COST] < cost(state.data())) {
                state = projected;
                ++c.jumps;
                evaluate(dec, state.data(), y.data());
                decode(d, y.data(), c.target);
                c.inert.transition(c.shown, c.target);
            }
        }
        evaluate(step, state.data(), deriv.data());
        for (int i = 0; i < S; ++i) state[size_t(i)] += deriv[size_t(i)] * dt;
        evaluate(dec, state.data(), y.data());
        decode(d, y.data(), c.source);
        c.finish(dt);
        us[k] = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
        if (c.searches != before) searched.push_back(us[k]);
    }
    return summarize(us, searched, c);
}

std::string pass_json(const std::vector<Pass>& p) {
    std::string out;
    const char* names[] = {"median_us", "mean_us", "searching_us", "searches", "jumps"};
    for (int f = 0; f < 5; ++f) {
        out += std::string(f ? ", " : "") + "\"" + names[f] + "\": [";
        for (size_t r = 0; r < p.size(); ++r) {
            char b[48];
            const double v = f == 0 ? p[r].median_us : f == 1 ? p[r].mean_us : f == 2 ? p[r].searching_us
                           : f == 3 ? p[r].searches : p[r].jumps;
            std::snprintf(b, sizeof b, "%s%.4f", r ? ", " : "", v);
            out += b;
        }
        out += "]";
    }
    return out;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 3) {
        std::fprintf(stderr, "usage: %s FRAMES.bin ROUNDS\n", argv[0]);
        return 2;
    }
    static Data d;
    if (!read_data(argv[1], d)) {
        std::fprintf(stderr, "%s: not a frame reference file (truncated or inconsistent)\n", argv[1]);
        return 1;
    }
    const int rounds = std::max(1, std::atoi(argv[2]));
    Boxes large, small;
    large.build(d, 64);
    small.build(d, 16);
    // the start state: the projector on the start frame's features (in the networks' space)
    std::vector<float> in(size_t(d.D)), start(size_t(d.nets[2].n_out)), y(size_t(d.nets[0].n_out));
    for (int i = 0; i < d.D; ++i) in[size_t(i)] = d.net_of_raw(i, d.raw(i, d.X[size_t(d.start) * d.D + i]));
    evaluate(d.nets[2], in.data(), start.data());
    std::vector<Pass> lmm, mm;
    std::string checks;
    for (int r = 0; r < rounds; ++r) {          // alternating: LMM, MM, LMM, MM ...
        lmm.push_back(run_lmm(d, start));
        mm.push_back(run_mm(d, large, small, r == 0 ? &checks : nullptr));
    }
    Pose p;
    p.resize(size_t(d.J));
    evaluate(d.nets[0], start.data(), y.data());
    decode(d, y.data(), p);
    std::printf("{\"lmm\": {%s}, \"mm\": {%s}, \"searches\": [%s], \"start_state\": [", pass_json(lmm).c_str(),
                pass_json(mm).c_str(), checks.c_str());
    for (size_t i = 0; i < start.size(); ++i) std::printf("%s%.9g", i ? ", " : "", double(start[i]));
    std::printf("], \"start_rotations\": [");
    for (const Q& q : p.r)
        std::printf("%s[%.9g, %.9g, %.9g, %.9g]", &q == &p.r[0] ? "" : ", ", double(q.w), double(q.x), double(q.y),
                    double(q.z));
    std::printf("]}\n");
    return 0;
}
