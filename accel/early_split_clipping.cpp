#include "accel/early_split_clipping.h"

#include "accel/binned_sah.h"
#include "accel/parallel.h"
#include "accel/triangle_clipping.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <stdexcept>
#include <string>

namespace canopy {
namespace {

constexpr size_t kGrain = 1024;

// Alg. 4 with an explicit stack; depth-first, left before right, so the pieces come out in a fixed order.
template <class Emit>
uint32_t clip_until_small(const Triangle& t, const BBox& whole, float sa_max, Emit&& emit) {
    struct Item { BBox box; int depth; };
    Item stack[kMaxEscDepth + 2];
    int top = 0;
    stack[top++] = {whole, 0};
    uint32_t pieces = 0;
    while (top) {
        const Item item = stack[--top];
        const int axis = item.box.largest_axis();
        const float mid = item.box.center()[axis];
        const bool halvable = mid > item.box.lower[axis] && mid < item.box.upper[axis];
        if (item.box.area() <= sa_max || item.depth >= kMaxEscDepth || !halvable) {
            emit(item.box);
            ++pieces;
            continue;
        }
        const auto [left, right] = split_triangle_bounds(t, item.box, axis, mid);
        if (!right.empty()) stack[top++] = {right, item.depth + 1};
        if (!left.empty()) stack[top++] = {left, item.depth + 1};
    }
    return pieces;
}

uint64_t count_pieces(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs, float sa_max) {
    return parallel::reduce(
        refs.size(), kGrain, uint64_t{0},
        [&](size_t b, size_t e) {
            uint64_t sum = 0;
            for (size_t i = b; i < e; ++i)
                sum += refs[i].bounds().area() <= sa_max ? 1 : clip_until_small(triangles[refs[i].prim], refs[i].bounds(), sa_max, [](const BBox&) {});
            return sum;
        },
        [](uint64_t a, uint64_t b) { return a + b; });
}

}  // namespace

float automatic_sa_max(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs) {
    if (refs.empty()) return 0.0f;
    std::vector<float> areas(refs.size());
    parallel::for_each(refs.size(), 16 * 1024, [&](size_t i) { areas[i] = refs[i].bounds().area(); });
    const double k = std::getenv("ESC_K") ? std::atof(std::getenv("ESC_K")) : 4.0;
    const double q = std::getenv("ESC_Q") ? std::atof(std::getenv("ESC_Q")) : 0.5;
    const double g = std::getenv("ESC_G") ? std::atof(std::getenv("ESC_G")) : 0.5;
    auto nth = areas.begin() + std::ptrdiff_t(q * double(areas.size() - 1));
    std::nth_element(areas.begin(), nth, areas.end());
    float sa_max = float(k * *nth);
    if (!(sa_max > 0.0f)) return 0.0f;
    while (count_pieces(triangles, refs, sa_max) > uint64_t((1.0 + g) * double(refs.size()))) sa_max *= 2.0f;
    std::fprintf(stderr, "esc: sa_max %g (k %g q %g g %g) \n", sa_max, k, q, g);
    return sa_max;
}

std::vector<PrimRef> early_split_clip_refs(std::span<const Triangle> triangles, std::vector<PrimRef>&& refs, float sa_max) {
    if (!(sa_max > 0.0f))
        throw std::invalid_argument("esc: SA_max must be > 0 (or 0 in EscSettings for automatic), got " + std::to_string(sa_max));
    const size_t n = refs.size();
    std::vector<uint32_t> pieces(n);
    parallel::for_each(n, kGrain, [&](size_t i) {
        pieces[i] = refs[i].bounds().area() <= sa_max ? 1 : clip_until_small(triangles[refs[i].prim], refs[i].bounds(), sa_max, [](const BBox&) {});
    });
    std::vector<uint64_t> offset(n + 1, 0);
    for (size_t i = 0; i < n; ++i) offset[i + 1] = offset[i] + pieces[i];
    if (offset[n] == n) return std::move(refs);
    std::vector<PrimRef> out(offset[n]);
    parallel::for_each(n, kGrain, [&](size_t i) {
        if (pieces[i] == 1) {
            out[offset[i]] = refs[i];
            return;
        }
        PrimRef* next = &out[offset[i]];
        const uint32_t prim = refs[i].prim;
        clip_until_small(triangles[prim], refs[i].bounds(), sa_max, [&](const BBox& b) { *next++ = PrimRef{b.lower, prim, b.upper}; });
    });
    return out;
}

Bvh build_esc_with(BuildInput&& input, const BuildSettings& settings, const EscSettings& esc) {
    if (!(esc.sa_max >= 0.0f) || !std::isfinite(esc.sa_max))
        throw std::invalid_argument("esc: SA_max must be finite and >= 0 (0: automatic), got " + std::to_string(esc.sa_max));
    const auto start = std::chrono::steady_clock::now();
    const float sa_max = esc.sa_max > 0.0f ? esc.sa_max : automatic_sa_max(input.triangles, input.refs);
    if (sa_max > 0.0f) input.refs = early_split_clip_refs(input.triangles, std::move(input.refs), sa_max);
    const double split_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    const uint64_t capacity = input.refs.size();
    Bvh bvh = build_binned_sah(std::move(input), settings);
    bvh.split = {split_ms, capacity};
    return bvh;
}

Bvh build_esc(BuildInput&& input, const BuildSettings& settings) {
    return build_esc_with(std::move(input), settings, EscSettings{});
}

}  // namespace canopy
