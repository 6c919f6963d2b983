#include "accel/builders/early_split_clipping.h"
#include "accel/split_pass.h"

#include "accel/builders/binned_sah.h"
#include "accel/parallel.h"
#include "accel/triangle_clipping.h"

#include <algorithm>
#include <limits>
#include <cmath>
#include <stdexcept>
#include <string>

namespace canopy {
namespace {

constexpr size_t kGrain = 1024;
// The automatic SA_max's constants (early_split_clipping.h): split scenes whose boxes are filled below 10% on the
// whole, into pieces of at most 8 median ideal areas.
constexpr double kMaxFillToSplit = 0.1;
constexpr double kIdealAreasPerPiece = 8.0;

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

// A_ideal of Karras and Aila 2013 (sec. 5): the summed box areas of infinitely fine pieces of the triangle,
// twice its projected area on the three axis planes.
float ideal_area(const Triangle& t) {
    const Vec3 n = geometric_normal(t);
    return std::abs(n.x) + std::abs(n.y) + std::abs(n.z);
}

}  // namespace

float automatic_sa_max(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs) {
    const size_t n = refs.size();
    if (n == 0) return std::numeric_limits<float>::infinity();
    std::vector<float> ideal(n);
    parallel::for_each(n, 16 * 1024, [&](size_t i) { ideal[i] = ideal_area(triangles[refs[i].prim]); });
    const double ideal_sum = parallel::sum_in_order(n, 16 * 1024, [&](size_t i) { return double(ideal[i]); });
    const double box_sum = parallel::sum_in_order(n, 16 * 1024, [&](size_t i) { return double(refs[i].bounds().area()); });
    const double fill = box_sum > 0.0 ? ideal_sum / box_sum : 1.0;
    if (fill >= kMaxFillToSplit) return std::numeric_limits<float>::infinity();
    const auto median = ideal.begin() + std::ptrdiff_t(n / 2);
    std::nth_element(ideal.begin(), median, ideal.end());
    const auto sa_max = float(kIdealAreasPerPiece * double(*median));
    return sa_max > 0.0f ? sa_max : std::numeric_limits<float>::infinity();  // most triangles degenerate
}

std::vector<PrimRef> early_split_clip_refs(std::span<const Triangle> triangles, std::vector<PrimRef>&& refs, float sa_max,
                                           uint64_t max_references) {
    if (!(sa_max > 0.0f))
        throw std::invalid_argument("esc: SA_max must be > 0 (or 0 in EscSettings for automatic), got " + std::to_string(sa_max));
    const size_t n = refs.size();
    std::vector<uint32_t> pieces(n);
    std::vector<uint64_t> offset(n + 1, 0);
    // Terminates: once SA_max exceeds every box's area (at the latest when it overflows to infinity), each
    // triangle is one piece, and n references always fit.
    for (;; sa_max *= 2.0f) {
        parallel::for_each(n, kGrain, [&](size_t i) {
            pieces[i] = refs[i].bounds().area() <= sa_max ? 1 : clip_until_small(triangles[refs[i].prim], refs[i].bounds(), sa_max, [](const BBox&) {});
        });
        for (size_t i = 0; i < n; ++i) offset[i + 1] = offset[i] + pieces[i];
        if (offset[n] <= std::max<uint64_t>(max_references, n)) break;
    }
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
    auto clip = [&](std::span<const Triangle> triangles, std::vector<PrimRef>&& refs) {
        const float sa_max = esc.sa_max > 0.0f ? esc.sa_max : automatic_sa_max(triangles, refs);
        const auto cap = uint64_t(kMaxEscReferencesPerTriangle * double(refs.size()));
        return std::isfinite(sa_max) && sa_max > 0.0f ? early_split_clip_refs(triangles, std::move(refs), sa_max, cap)
                                                       : std::move(refs);
    };
    return build_after_split_pass(std::move(input), settings, clip, &build_binned_sah);
}

Bvh build_esc(BuildInput&& input, const BuildSettings& settings) {
    return build_esc_with(std::move(input), settings, EscSettings{});
}

}  // namespace canopy
