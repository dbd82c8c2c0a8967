// Per-call time of a plain C++ evaluation of our networks, for `lmm-studio bench` (issue 16).
//
// The same algorithm as the reference demo's runtime networks (row-major weights, normalise, for each
// layer: bias, then for every non-zero input one saxpy over the layer's outputs, ReLU between layers,
// denormalise; nnet_reference.h), built with the demo's flags (cpp_reference.FLAGS). `bench` writes our
// weights and real inputs from a controller run to a file, runs this program and compares its medians with
// ours, measured on the same machine in the same run.
//
// Input file (little-endian): "LMMNB1", int32 network count, then one block per network (described in
// nnet_reference.h, which reads and evaluates them).
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

#include "nnet_reference.h"

namespace {

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
