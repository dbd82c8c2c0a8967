/* The compiled filter of lmm.search_index.SearchIndex.group_search (see lmm/search_native.py).
 *
 * It walks three levels of bounding boxes (256, 32 and 8 frames) with a threshold that tightens as real
 * frames are costed, and returns every candidate frame whose total (cost + transition cost + bias) is within
 * a relative 1e-4 of the k-th best total: a superset of the frames that can be in the exact answer, which are
 * then ranked exactly as the brute force does: for a top-1 search here, else by numpy. Every cost is
 * numpy_row_cost, numpy's own sum where lmm/search_native.py has checked that it is (only then does this file
 * rank); where it is not, the margin is far wider than the rounding between the two sums, so the filter still
 * keeps every frame of the answer.
 *
 * One build runs at native speed on any x86-64: GCC's target_clones picks the widest instruction set at load.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#if defined(__GNUC__) && !defined(__clang__) && (defined(__x86_64__) || defined(__i386__))
/* dispatched on the CPU's features (an "arch=" clone would test the CPU model, not what it supports) */
#define CLONES __attribute__((target_clones("default", "avx2", "avx512f")))
#else
#define CLONES
#endif
/* every helper is inlined into each clone (a called function would run the default clone's instructions) */
#define INLINE static inline __attribute__((always_inline))

#define SLACK 0.9999f  /* a box bound shrunk by 1e-4 stays below every cost in the box, rounding included */
#define MAX_K 64
#define PER_TOP 8  /* large blocks per top block (lmm/search_native.py's TOP_BLOCK) */
/* a top block's PER_TOP large blocks at once (a plain loop over them was vectorised across dimensions, with
 * gathers: 3x slower) */
typedef float v8 __attribute__((vector_size(32)));
typedef int32_t vi8 __attribute__((vector_size(32)));

typedef struct {
    float best[MAX_K]; /* the k least totals seen, ascending (INFINITY: none yet) */
    int k;
    float scale;       /* |transition cost| + the largest |bias|: the margin's floor */
    float thr;         /* best[k-1] widened by the margin */
} kbest;

INLINE void kbest_set_thr(kbest *b) {
    float t = b->best[b->k - 1];
    b->thr = isinf(t) ? INFINITY : t + 1e-4f * (fabsf(t) + b->scale);
}

INLINE void kbest_push(kbest *b, float v) {
    int i = b->k - 1;
    if (!(v < b->best[i])) return;
    while (i > 0 && b->best[i - 1] > v) { b->best[i] = b->best[i - 1]; i--; }
    b->best[i] = v;
    kbest_set_thr(b);
}

/* squared distance from q to the box [lo, hi] over n dims */
INLINE float box_bound(const float *lo, const float *hi, const float *q, int n) {
    float acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    int d = 0;
    for (; d + 8 <= n; d += 8)
        for (int j = 0; j < 8; j++) {
            float c = q[d + j] < lo[d + j] ? lo[d + j] : (q[d + j] > hi[d + j] ? hi[d + j] : q[d + j]);
            float g = q[d + j] - c;
            acc[j] += g * g;
        }
    float s = 0.0f;
    for (; d < n; d++) {
        float c = q[d] < lo[d] ? lo[d] : (q[d] > hi[d] ? hi[d] : q[d]);
        float g = q[d] - c;
        s += g * g;
    }
    return s + ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
}

/* The squared distance of a row to q summed exactly as numpy's einsum("ij,ij->i") sums a float32 row of n
 * values (numpy's 128-bit baseline loop: four lanes, each over elements l, l + 4, ...: per 16 elements the
 * lanes take the products 12-15, 8-11, 4-7, 0-3 in that order, then the tail's products four at a time, the
 * last four zero-filled; then (lane 0 + lane 1) + (lane 2 + lane 3)), with the same float32 roundings (the
 * file is built with -ffp-contract=off: no fused multiply-adds). lmm/search_native.py checks it against numpy
 * on the index's own rows before it is used; with another numpy that sums otherwise, numpy costs the frames. */
INLINE float numpy_row_cost(const float *x, const float *q, int n) {
    float v[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    int d = 0;
    for (; n - d >= 16; d += 16)
        for (int l = 0; l < 4; l++) {
            float g0 = x[d + l] - q[d + l], g1 = x[d + 4 + l] - q[d + 4 + l];
            float g2 = x[d + 8 + l] - q[d + 8 + l], g3 = x[d + 12 + l] - q[d + 12 + l];
            float p0 = g0 * g0, p1 = g1 * g1, p2 = g2 * g2, p3 = g3 * g3;
            v[l] = p0 + (p1 + (p2 + (p3 + v[l])));
        }
    for (; d < n; d += 4)
        for (int l = 0; l < 4; l++) {
            float p = 0.0f;
            if (d + l < n) {
                float g = x[d + l] - q[d + l];
                p = g * g;
            }
            v[l] = p + v[l];
        }
    return (v[0] + v[1]) + (v[2] + v[3]);
}

typedef struct {
    const float *rows, *g_lo, *g_hi, *l2_lo, *l2_hi, *bias, *small_min, *large_min, *q;
    int dims, per, sb;
    int64_t n_large;
    float tc;
    int64_t wlo, whi;   /* the exclusion window [wlo, whi): not candidates in this search */
    int64_t *out;
    float *out_key;
    int n_out, max_out;
} scan;

/* keep only the collected frames within the threshold; 0 when the buffer is still full */
INLINE int compact(scan *s, const kbest *b) {
    int j = 0;
    for (int i = 0; i < s->n_out; i++)
        if (s->out_key[i] <= b->thr) { s->out[j] = s->out[i]; s->out_key[j] = s->out_key[i]; j++; }
    s->n_out = j;
    return j < s->max_out;
}

/* the small blocks of one large block, then their frames; 0 on overflow */
INLINE int visit_large(scan *s, kbest *b, int64_t large) {
    const int d = s->dims, per = s->per, sb = s->sb;
    const float *lo = s->l2_lo + large * per * d, *hi = s->l2_hi + large * per * d;
    for (int j = 0; j < per; j++) {
        int64_t small = large * per + j;
        float bound = box_bound(lo + j * d, hi + j * d, s->q, d) * SLACK + s->tc + s->small_min[small];
        if (!(bound <= b->thr)) continue;
        for (int r = 0; r < sb; r++) {
            int64_t f = small * sb + r;
            float fb = s->bias[f];
            if (isinf(fb) || (f >= s->wlo && f < s->whi)) continue;
            float key = (numpy_row_cost(s->rows + f * d, s->q, d) + s->tc) + fb;
            if (!(key <= b->thr)) continue;
            kbest_push(b, key);
            if (s->n_out == s->max_out && !compact(s, b)) return 0;
            s->out[s->n_out] = f;
            s->out_key[s->n_out] = key;
            s->n_out++;
        }
    }
    return 1;
}

/* the large blocks of one top block, then their small blocks and frames; 0 on overflow */
INLINE int visit_top(scan *s, kbest *b, int64_t top) {
    const int d = s->dims;
    const float *lo = s->g_lo + top * d * PER_TOP, *hi = s->g_hi + top * d * PER_TOP;
    v8 acc = {0, 0, 0, 0, 0, 0, 0, 0};
    const v8 zero = {0, 0, 0, 0, 0, 0, 0, 0};
    for (int j = 0; j < d; j++) {   /* a missing block's box is empty (lo inf, hi -inf): its bound is inf */
        v8 l, h;
        __builtin_memcpy(&l, lo + j * PER_TOP, sizeof l);
        __builtin_memcpy(&h, hi + j * PER_TOP, sizeof h);
        const v8 qj = zero + s->q[j];
        v8 below = l - qj, above = qj - h;
        below = (v8)((vi8)below & (below > zero));   /* max(x, 0): the bits of x where x > 0 */
        above = (v8)((vi8)above & (above > zero));
        v8 g = below + above;
        acc += g * g;
    }
    const int64_t first = top * PER_TOP;
    for (int i = 0; i < PER_TOP && first + i < s->n_large; i++)
        if (acc[i] * SLACK + s->tc + s->large_min[first + i] <= b->thr && !visit_large(s, b, first + i)) return 0;
    return 1;
}

/* The filter's arguments that stay the same from one search to the next: the index's arrays, the bias
 * arrays of the tag groups (and each top block's least bias), the query buffer and the outputs, in one
 * struct that lmm/search_native.py keeps, so that a call passes six values. */
typedef struct {
    const float *rows, *t_lo, *t_hi;
    int64_t n_top;
    int per_top;
    const float *g_lo, *g_hi, *l2_lo, *l2_hi;
    int64_t n_large;
    int per, sb, dims;
    const float *bias, *small_min, *large_min, *q;
    const float *top_min;   /* the least bias of each top block's large blocks (n_top) */
    float *tb;
    int64_t *out;
    float *out_key;
    int max_out;
    float *diff;            /* (diff_rows, dims): the rows minus the query of the frames returned */
    int diff_rows;
    int exact;              /* 1: numpy_row_cost sums as numpy does here (checked), so a top-1 search ranks here */
    double *res;            /* the top-1 answer: ranked (1, or 0: numpy ranks), frame (-1: none), total, bias,
                             * the playing frame's cost (NaN when it does not compete) */
} filter_args;

/* Frames (ascending within each visit, unordered overall) that may be in the top k; returns their count,
 * or -1 when more than max_out are within the margin (the caller falls back to numpy).
 *
 * Three levels of boxes, every dimension: top blocks of per_top (PER_TOP) large blocks, t_lo/t_hi
 * (dims, n_top); large blocks grouped by top block, g_lo/g_hi (n_top, dims, per_top); small blocks,
 * l2_lo/l2_hi (n_large, per * dims).
 * rows (n_pad, dims) the features padded to whole large blocks; bias (n_pad) each frame's bias, INFINITY
 * for frames that are not candidates; small_min/large_min/top_min the least bias per block; cont_key the
 * playing frame's total, the first threshold (INFINITY when it does not compete); tb scratch (n_top).
 *
 * The top bounds read a fifth of the memory that bounding every large block over 16 dims read (27 floats
 * per 256 frames against 16 per 32); a top block's large boxes are then one contiguous 1.7 kB piece. The most
 * promising top block is visited first (a tight threshold early), then the others in order: visiting them
 * in ascending bound (a sort) visited 15% fewer but cost more than it saved.
 */
INLINE int filter(const filter_args *a, float tc, float spread, float cont_key, int k, int64_t wlo, int64_t whi) {
    const int dims = a->dims;
    const int64_t n_top = a->n_top, n_large = a->n_large;
    const float *q = a->q, *bias = a->bias, *large_min = a->large_min;
    float *tb = a->tb;
    if (k < 1 || k > MAX_K || a->per_top != PER_TOP) return -1;
    kbest b;
    b.k = k;
    b.scale = fabsf(tc) + spread;
    for (int i = 0; i < k; i++) b.best[i] = INFINITY;
    kbest_set_thr(&b);
    kbest_push(&b, cont_key);
    /* 1. the bound of every top block, dimension by dimension (long loops along the blocks) */
    for (int64_t t = 0; t < n_top; t++) tb[t] = 0.0f;
    for (int j = 0; j < dims; j++) {
        const float qj = q[j];
        const float *lo = a->t_lo + j * n_top, *hi = a->t_hi + j * n_top;
        for (int64_t t = 0; t < n_top; t++) {
            float c = qj < lo[t] ? lo[t] : (qj > hi[t] ? hi[t] : qj);
            float g = qj - c;
            tb[t] += g * g;
        }
    }
    int64_t first = 0;
    float least = INFINITY;
    for (int64_t t = 0; t < n_top; t++) {
        tb[t] = tb[t] * SLACK + tc + a->top_min[t];
        if (tb[t] < least) { least = tb[t]; first = t; }
    }
    if (isinf(least)) return 0;
    scan s = {a->rows, a->g_lo, a->g_hi, a->l2_lo, a->l2_hi, bias, a->small_min, large_min, q, dims, a->per, a->sb,
              n_large, tc, wlo, whi, a->out, a->out_key, 0, a->max_out};
    /* 2. the most promising block first (a tight threshold early), then every block that may hold a frame */
    if (!visit_top(&s, &b, first)) return -1;
    for (int64_t t = 0; t < n_top; t++)
        if (t != first && tb[t] <= b.thr && !visit_top(&s, &b, t)) return -1;
    compact(&s, &b);
    return s.n_out;
}

static int by_frame(const void *x, const void *y) {
    int64_t a = *(const int64_t *)x, b = *(const int64_t *)y;
    return (a > b) - (a < b);
}

/* A top-1 search's answer from the filter's n frames (ascending in out) and the playing frame cont_frame
 * (-1: it does not compete; cont_cost its cost, cont_bias its group's bias), ranked as lmm.search_ranking.rank_top1 ranks them,
 * every cost by numpy_row_cost: each frame's total (cost + tc) + its bias in float32; the least, unless it
 * ties with another's or the playing frame's total (then 0: numpy ranks); the playing frame's total is its
 * cost + its bias, and it wins when lower. Writes a->res and returns 1 when ranked. */
INLINE int rank_top1(const filter_args *a, int n, float tc, int64_t cont_frame, float cont_cost, float cont_bias) {
    const int d = a->dims;
    double *res = a->res;
    float best = INFINITY;
    int64_t best_f = -1;
    int tie = 0;
    for (int i = 0; i < n; i++) {
        const int64_t f = a->out[i];
        const float key = (numpy_row_cost(a->rows + f * d, a->q, d) + tc) + a->bias[f];
        if (key < best) { best = key; best_f = f; tie = 0; }
        else if (key == best) tie = 1;
    }
    res[4] = cont_frame >= 0 ? cont_cost : NAN;
    const int cont = cont_frame >= 0 && cont_cost == cont_cost;    /* NaN: it does not compete */
    const float cont_total = cont ? cont_cost + cont_bias : INFINITY;
    res[0] = 1.0;
    if (best_f < 0 || !(best < INFINITY)) {      /* no candidate: the playing frame, if it competes */
        res[1] = cont ? (double)cont_frame : -1.0;
        res[2] = cont_total;
        res[3] = cont_bias + 0.0f;
        return 1;
    }
    if (tie || (cont && cont_total == best)) { res[0] = 0.0; return 0; }
    if (cont && cont_total < best) {
        res[1] = (double)cont_frame; res[2] = cont_total; res[3] = cont_bias + 0.0f;
    } else {
        res[1] = (double)best_f; res[2] = best; res[3] = tc + a->bias[best_f];
    }
    return 1;
}

/* The filter as a tick's search calls it (lmm.search_index.SearchIndex.group_search): the playing frame
 * cont_frame (-1: it does not compete) with its group's bias cont_bias gives the first threshold; the frames of the exclusion window [wlo, whi) are not
 * candidates; the frames come back ascending in out[0..n), and out[n] is cont_frame when it competes (out
 * holds max_out + 1). For a top-1 search with a->exact, the answer is ranked here (rank_top1: a->res); when
 * it is not (another k, or a tie), and those n (+ 1) frames fit diff_rows, diff holds their rows minus the
 * query, which the caller reduces to their costs. Returns n, or -1 as filter() does. */
CLONES
int lmm_tick_filter(const filter_args *a, float tc, float spread, int64_t cont_frame, float cont_bias, int k,
                    int64_t wlo, int64_t whi) {
    const float cont_cost = cont_frame >= 0 ? numpy_row_cost(a->rows + cont_frame * a->dims, a->q, a->dims) : NAN;
    const float cont_key = cont_frame >= 0 ? cont_cost + cont_bias : INFINITY;
    a->res[0] = 0.0;
    int n = filter(a, tc, spread, cont_key, k, wlo, whi);
    if (n < 0) return n;
    int64_t *out = a->out;
    if (n > 64) {
        qsort(out, (size_t)n, sizeof *out, by_frame);
    } else {
        for (int i = 1; i < n; i++) {    /* usually a handful of frames, mostly ascending already */
            int64_t f = out[i];
            int j = i - 1;
            while (j >= 0 && out[j] > f) { out[j + 1] = out[j]; j--; }
            out[j + 1] = f;
        }
    }
    if (k == 1 && a->exact && rank_top1(a, n, tc, cont_frame, cont_cost, cont_bias)) return n;
    if (cont_frame >= 0) out[n] = cont_frame;
    /* each returned frame's row minus the query, as numpy's float32 subtraction makes it (one rounding per
     * element, whatever the order), for the caller's cost reduction: no row gather there */
    const int m = n + (cont_frame >= 0), d = a->dims;
    if (m <= a->diff_rows)
        for (int i = 0; i < m; i++) {
            const float *x = a->rows + out[i] * d;
            float *o = a->diff + (int64_t)i * d;
            for (int j = 0; j < d; j++) o[j] = x[j] - a->q[j];
        }
    return n;
}

/* numpy_row_cost of each of n rows (n, dims) to q, into out: lmm/search_native.py compares them with
 * numpy's before it lets the filter rank. */
CLONES
void lmm_numpy_costs(const float *rows, int64_t n, int dims, const float *q, float *out) {
    for (int64_t i = 0; i < n; i++) out[i] = numpy_row_cost(rows + i * dims, q, dims);
}
