// The networks of the C++ references of `lmm-studio bench`: reading one network block of the file `bench`
// writes (app/commands/cpp_reference.py, `write_networks`) and evaluating it as the reference demo's runtime
// does (row-major weights, normalise, for each layer: bias, then for every non-zero input one saxpy over
// the layer's outputs, ReLU between layers, denormalise). Shared by nnet_reference.cpp (each network
// alone) and frame_reference.cpp (whole frames); each program is one translation unit.
//
// A network block (little-endian): int32 name length, name bytes, int32 skip (projector: input added to
// the first outputs), int32 layer count L, int32 input size, float32 in_mean, in_std (input size each),
// int32 output size, float32 out_mean, out_std; per layer int32 rows, int32 cols, float32 weights
// (rows x cols, row-major), float32 bias (cols); int32 sample count S and float32 samples (S x input size).
#pragma once

#include <cstdint>
#include <cstdio>
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
    // n values of type T (at most 2^28; a bad count or a short file clears ok)
    template <class T>
    std::vector<T> array(int64_t n) {
        std::vector<T> v;
        if (!ok || n < 0 || n > (int64_t(1) << 28)) { ok = false; return v; }
        v.resize(size_t(n));
        ok = std::fread(v.data(), sizeof(T), v.size(), f) == v.size();
        return v;
    }
    std::vector<float> floats(int64_t n) { return array<float>(n); }
    std::vector<int32_t> ints(int64_t n) { return array<int32_t>(n); }
    std::vector<uint8_t> bytes(int64_t n) { return array<uint8_t>(n); }
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

}  // namespace
