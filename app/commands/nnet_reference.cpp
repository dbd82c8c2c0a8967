// Per-call time of a plain C++ evaluation of our networks, for `lmm-studio bench` (issue 16).
//
// The same algorithm as the reference demo's runtime networks (row-major weights, normalise, for each
// layer: bias, then for every non-zero input one saxpy over the layer's outputs, ReLU between layers,
// denormalise), built with the demo's release flags (-O3 -ffast-math). `bench` writes our weights and
// real inputs from a controller run to a file, runs this program and compares its medians with ours,
// measured on the same machine in the same run.
//
// Input file (little-endian): "LMMNB1", int32 network count, then per network: int32 name length,
// name bytes, int32 skip (projector: input added to the first outputs), int32 layer count L, int32 input
// size, float32 in_mean, in_std (input size each), int32 output size, float32 out_mean, out_std; per
// layer int32 rows, int32 cols, float32 weights (rows x cols, row-major), float32 bias (cols); int32
// sample count S and float32 samples (S x input size).
// Output: one JSON object on stdout, {"name": {"us": median per-call time, "y0": outputs for the first
// sample}, ...} (`bench` checks y0 against our evaluation: the time is of the same computation); a
// message on stderr and exit 1 on a bad file.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace {

struct Reader {
    FILE* f;
    bool ok = true;
    int32_t i32() {
        int32_t v = 0;
        ok = ok && std::fread(&v, sizeof v, 1, f) == 1;
        return v;
    }
    std::vector<float> floats(int64_t n) {
        std::vector<float> v;
        if (!ok || n < 0 || n > (int64_t(1) << 28)) { ok = false; return v; }
        v.resize(size_t(n));
        ok = std::fread(v.data(), sizeof(float), v.size(), f) == v.size();
        return v;
    }
};

struct Layer {
    int rows = 0, cols = 0;
    std::vector<float> w, b;
};

struct Net {
    std::string name;
    bool skip = false;
    int n_in = 0, n_out = 0;
    std::vector<float> in_mean, in_std, out_mean, out_std, samples;
    std::vector<Layer> layers;
    std::vector<std::vector<float>> act;   // act[0]: normalised input, act[i + 1]: layer i's output
};

void linear(float* __restrict out, const float* __restrict in, const Layer& l) {
    const float* __restrict w = l.w.data();
    for (int j = 0; j < l.cols; ++j) out[j] = l.b[size_t(j)];
    for (int i = 0; i < l.rows; ++i) {
        const float a = in[i];
        if (a == 0.0f) continue;               // ReLU zeros: the row adds nothing
        const float* __restrict row = w + size_t(i) * size_t(l.cols);
        for (int j = 0; j < l.cols; ++j) out[j] += a * row[j];
    }
}

void evaluate(Net& n, const float* x, float* y) {
    float* h0 = n.act[0].data();
    for (int i = 0; i < n.n_in; ++i) h0[i] = (x[i] - n.in_mean[size_t(i)]) / n.in_std[size_t(i)];
    const size_t last = n.layers.size() - 1;
    for (size_t k = 0; k < n.layers.size(); ++k) {
        float* out = n.act[k + 1].data();
        linear(out, n.act[k].data(), n.layers[k]);
        if (k != last)
            for (int j = 0; j < n.layers[k].cols; ++j) out[j] = out[j] > 0.0f ? out[j] : 0.0f;
    }
    const float* o = n.act.back().data();
    for (int j = 0; j < n.n_out; ++j) y[j] = o[j] * n.out_std[size_t(j)] + n.out_mean[size_t(j)];
    if (n.skip)
        for (int i = 0; i < n.n_in && i < n.n_out; ++i) y[i] += x[i];
}

bool read_net(Reader& r, Net& n) {
    const int32_t name_len = r.i32();
    if (!r.ok || name_len <= 0 || name_len > 64) return false;
    n.name.resize(size_t(name_len));
    r.ok = std::fread(&n.name[0], 1, n.name.size(), r.f) == n.name.size();
    n.skip = r.i32() != 0;
    const int32_t count = r.i32();
    n.n_in = r.i32();
    if (!r.ok || count < 1 || count > 16 || n.n_in < 1 || n.n_in > 65536) return false;
    n.in_mean = r.floats(n.n_in);
    n.in_std = r.floats(n.n_in);
    n.n_out = r.i32();
    if (!r.ok || n.n_out < 1 || n.n_out > 65536) return false;
    n.out_mean = r.floats(n.n_out);
    n.out_std = r.floats(n.n_out);
    int prev = n.n_in;
    n.layers.resize(size_t(count));
    for (Layer& l : n.layers) {
        l.rows = r.i32();
        l.cols = r.i32();
        if (!r.ok || l.rows != prev || l.cols < 1 || l.cols > 65536) return false;
        l.w = r.floats(int64_t(l.rows) * l.cols);
        l.b = r.floats(l.cols);
        prev = l.cols;
    }
    if (prev != n.n_out) return false;
    const int32_t n_samples = r.i32();
    if (!r.ok || n_samples < 1 || n_samples > 100000) return false;
    n.samples = r.floats(int64_t(n_samples) * n.n_in);
    n.act.assign(1, std::vector<float>(size_t(n.n_in)));
    for (const Layer& l : n.layers) n.act.emplace_back(size_t(l.cols));
    return r.ok;
}

// Median over `reps` single calls (after one pass over the samples to warm the caches), cycling the samples.
double median_call_us(Net& n, int reps) {
    const int n_samples = int(n.samples.size() / size_t(n.n_in));
    std::vector<float> y(static_cast<size_t>(n.n_out));
    float sink = 0.0f;
    for (int s = 0; s < n_samples; ++s) {
        evaluate(n, n.samples.data() + size_t(s) * size_t(n.n_in), y.data());
        sink += y[0];
    }
    std::vector<double> us(static_cast<size_t>(reps));
    for (int k = 0; k < reps; ++k) {
        const float* x = n.samples.data() + size_t(k % n_samples) * size_t(n.n_in);
        const auto t0 = std::chrono::steady_clock::now();
        evaluate(n, x, y.data());
        const auto t1 = std::chrono::steady_clock::now();
        sink += y[0];
        us[size_t(k)] = std::chrono::duration<double, std::micro>(t1 - t0).count();
    }
    std::nth_element(us.begin(), us.begin() + reps / 2, us.end());
    if (sink == 12345.678f) std::fputc(' ', stderr);   // keep the results live
    return us[size_t(reps / 2)];
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: %s NETWORKS.bin [REPEATS]\n", argv[0]);
        return 2;
    }
    const int reps = argc > 2 ? std::max(1, std::atoi(argv[2])) : 2000;
    FILE* f = std::fopen(argv[1], "rb");
    if (!f) {
        std::fprintf(stderr, "%s: cannot open\n", argv[1]);
        return 1;
    }
    Reader r{f};
    char magic[6] = {0};
    r.ok = std::fread(magic, 1, 6, f) == 6 && std::memcmp(magic, "LMMNB1", 6) == 0;
    const int32_t count = r.i32();
    if (!r.ok || count < 1 || count > 16) {
        std::fprintf(stderr, "%s: not a network file (bad header)\n", argv[1]);
        std::fclose(f);
        return 1;
    }
    std::vector<Net> nets(static_cast<size_t>(count));
    for (size_t i = 0; i < nets.size(); ++i) {
        if (!read_net(r, nets[i])) {
            std::fprintf(stderr, "%s: network %zu: truncated or inconsistent\n", argv[1], i);
            std::fclose(f);
            return 1;
        }
    }
    std::fclose(f);
    std::printf("{");
    for (size_t i = 0; i < nets.size(); ++i) {
        Net& n = nets[i];
        std::vector<float> y0(static_cast<size_t>(n.n_out));
        evaluate(n, n.samples.data(), y0.data());
        std::printf("%s\"%s\": {\"us\": %.4f, \"y0\": [", i ? ", " : "", n.name.c_str(), median_call_us(n, reps));
        for (size_t j = 0; j < y0.size(); ++j) std::printf("%s%.9g", j ? ", " : "", double(y0[j]));
        std::printf("]}");
    }
    std::printf("}\n");
    return 0;
}
