#include "accel/builders/presplit.h"
#include "accel/split_pass.h"

#include "accel/builders/binned_sah.h"
#include "accel/parallel.h"
#include "accel/triangle_clipping.h"

#include <bit>
#include <cmath>
#include <stdexcept>

namespace canopy {
namespace {

constexpr size_t kGrain = 16 * 1024;
constexpr int kGridBits = 31;  // grid planes at multiples of 2^-31 of the scene box, on every axis

struct GridPlane {
    int axis = -1;
    int level = 0;  // 1 for the scene's mid plane, 2 for its quarter planes, ...
    float position = 0;
};

// The most important grid plane strictly inside `box` (sec. 5: the split plane of the coarsest grid level that
// crosses the box): on each axis the highest bit in which the box's grid coordinates differ gives the level.
// Ties go to the axis of largest extent. axis < 0 when no grid plane crosses the box.
GridPlane most_important_plane(const BBox& box, const BBox& scene) {
    GridPlane best;
    for (int axis = 0; axis < 3; ++axis) {
        const double extent = double(scene.upper[axis]) - double(scene.lower[axis]);
        if (extent <= 0.0) continue;
        auto grid = [&](float x) {
            const double u = std::clamp((double(x) - double(scene.lower[axis])) / extent, 0.0, 1.0);
            return uint32_t(std::min(u * double(1u << kGridBits), double((1u << kGridBits) - 1)));
        };
        const uint32_t lo = grid(box.lower[axis]), hi = grid(box.upper[axis]);
        if (lo == hi) continue;
        const int bit = std::bit_width(lo ^ hi) - 1;
        const uint32_t plane = (hi >> bit) << bit;
        const auto position = float(double(scene.lower[axis]) + extent * double(plane) / double(1u << kGridBits));
        if (!(position > box.lower[axis] && position < box.upper[axis])) continue;
        const int level = kGridBits - bit;
        const bool wider = best.axis >= 0 && box.extent()[axis] > box.extent()[best.axis];
        if (best.axis < 0 || level < best.level || (level == best.level && wider)) best = {axis, level, position};
    }
    return best;
}

// Sec. 5: p_t = (X^i (A_aabb - A_ideal))^Y with X = 2, Y = 1/3 and i = -level. A_ideal, the summed box areas of
// infinitely fine pieces, is twice the triangle's projected area on the three axis planes: |n_x| + |n_y| + |n_z|.
float split_priority(const Triangle& t, const BBox& scene) {
    const BBox box = BBox::of(t);
    const GridPlane plane = most_important_plane(box, scene);
    if (plane.axis < 0) return 0.0f;
    const Vec3 n = geometric_normal(t);
    const double ideal = std::abs(double(n.x)) + std::abs(double(n.y)) + std::abs(double(n.z));
    const double excess = std::max(0.0, double(box.area()) - ideal);
    return float(std::cbrt(std::ldexp(excess, -plane.level)));
}

// Splits a piece into `splits + 1` pieces at the most important grid planes, sharing the remaining splits
// between the halves in proportion to their largest extent; calls emit(piece) for each. Returns pieces made.
template <class Emit>
uint32_t split_recursively(const Triangle& t, const BBox& piece, uint32_t splits, const BBox& scene, Emit&& emit) {
    const GridPlane plane = splits ? most_important_plane(piece, scene) : GridPlane{};
    if (plane.axis < 0) {
        emit(piece);
        return 1;
    }
    const auto [left, right] = split_triangle_bounds(t, piece, plane.axis, plane.position);
    if (left.empty() || right.empty()) return split_recursively(t, left.empty() ? right : left, splits - 1, scene, emit);
    const float wl = glm::max(left.extent().x, glm::max(left.extent().y, left.extent().z));
    const float wr = glm::max(right.extent().x, glm::max(right.extent().y, right.extent().z));
    const uint32_t rest = splits - 1;
    const auto to_left = uint32_t(std::lround(double(rest) * wl / std::max(double(wl) + double(wr), 1e-30)));
    return split_recursively(t, left, std::min(to_left, rest), scene, emit) +
           split_recursively(t, right, rest - std::min(to_left, rest), scene, emit);
}

uint64_t total_splits(const std::vector<float>& priority, double scale) {
    return parallel::reduce(
        priority.size(), kGrain, uint64_t{0},
        [&](size_t b, size_t e) {
            uint64_t sum = 0;
            for (size_t i = b; i < e; ++i) sum += uint64_t(std::floor(double(priority[i]) * scale));
            return sum;
        },
        [](uint64_t a, uint64_t b) { return a + b; });
}

// The scale D of sec. 5 (s_t = floor(D p_t)): the largest found by bisection whose total stays in the budget.
double budget_scale(const std::vector<float>& priority, uint64_t budget) {
    const double sum = parallel::sum_in_order(priority.size(), kGrain, [&](size_t i) { return double(priority[i]); });
    if (sum <= 0.0 || budget == 0) return 0.0;
    // floor loses less than one split per triangle: D = budget / sum fits, (budget + n) / sum reaches the budget.
    double lo = double(budget) / sum, hi = (double(budget) + double(priority.size())) / sum;
    for (int i = 0; i < 16; ++i) {
        const double mid = 0.5 * (lo + hi);
        (total_splits(priority, mid) <= budget ? lo : hi) = mid;
    }
    return lo;
}

}  // namespace

std::vector<PrimRef> presplit_refs(std::span<const Triangle> triangles, std::vector<PrimRef>&& refs, float budget_fraction) {
    if (!(budget_fraction >= 0.0f) || !std::isfinite(budget_fraction))
        throw std::invalid_argument("presplit: the split budget must be a finite fraction >= 0, got " + std::to_string(budget_fraction));
    const size_t n = refs.size();
    if (n == 0 || budget_fraction == 0.0f) return std::move(refs);
    const BBox scene = parallel::reduce(
        n, kGrain, BBox{},
        [&](size_t b, size_t e) {
            BBox box;
            for (size_t i = b; i < e; ++i) box.extend(refs[i].bounds());
            return box;
        },
        [](BBox a, const BBox& b) { return merge(a, b); });

    std::vector<float> priority(n);
    parallel::for_each(n, kGrain, [&](size_t i) { priority[i] = split_priority(triangles[refs[i].prim], scene); });
    const double scale = budget_scale(priority, uint64_t(double(budget_fraction) * double(n)));

    // Two passes over the same deterministic splitting: count the pieces, then write them at their offsets.
    std::vector<uint32_t> pieces(n);
    auto splits_of = [&](size_t i) { return uint32_t(std::floor(double(priority[i]) * scale)); };
    parallel::for_each(n, kGrain / 16, [&](size_t i) {
        pieces[i] = splits_of(i) ? split_recursively(triangles[refs[i].prim], refs[i].bounds(), splits_of(i), scene, [](const BBox&) {}) : 1;
    });
    std::vector<uint64_t> offset(n + 1, 0);
    for (size_t i = 0; i < n; ++i) offset[i + 1] = offset[i] + pieces[i];
    std::vector<PrimRef> out(offset[n]);
    parallel::for_each(n, kGrain / 16, [&](size_t i) {
        if (pieces[i] == 1) {
            out[offset[i]] = refs[i];
            return;
        }
        PrimRef* next = &out[offset[i]];
        const uint32_t prim = refs[i].prim;
        split_recursively(triangles[prim], refs[i].bounds(), splits_of(i), scene,
                          [&](const BBox& b) { *next++ = PrimRef{b.lower, prim, b.upper}; });
    });
    return out;
}

Bvh build_presplit_with(BuildInput&& input, const BuildSettings& settings, const PresplitSettings& presplit) {
    auto split = [&](std::span<const Triangle> triangles, std::vector<PrimRef>&& refs) {
        return presplit_refs(triangles, std::move(refs), presplit.budget);
    };
    return build_after_split_pass(std::move(input), settings, split, &build_binned_sah);
}

Bvh build_presplit(BuildInput&& input, const BuildSettings& settings) {
    return build_presplit_with(std::move(input), settings, PresplitSettings{});
}

}  // namespace canopy
