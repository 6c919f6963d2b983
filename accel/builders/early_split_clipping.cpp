#include "accel/builders/early_split_clipping.h"
#include "accel/split_pass.h"

#include "accel/builders/binned_sah.h"
#include "accel/parallel.h"
#include "accel/triangle_clipping.h"

#include <algorithm>
#include <atomic>
#include <limits>
#include <numeric>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace canopy {
namespace {

constexpr size_t kGrain = 1024;
// The automatic SA_max's pieces (early_split_clipping.h): at most 8 median ideal areas.
constexpr double kIdealAreasPerPiece = 8.0;
constexpr size_t kSampledReferences = 4096;  // where SA_max must grow to fit the budget, a guess from this many

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

// A_ideal of each reference's triangle.
std::vector<float> ideal_areas(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs) {
    std::vector<float> ideal(refs.size());
    parallel::for_each(refs.size(), 16 * 1024, [&](size_t i) { ideal[i] = ideal_area(triangles[refs[i].prim]); });
    return ideal;
}

// The median of `values`, reordered (0 when empty).
double median_of(std::vector<float>& values) {
    if (values.empty()) return 0.0;
    const auto median = values.begin() + std::ptrdiff_t(values.size() / 2);
    std::nth_element(values.begin(), median, values.end());
    return *median;
}

}  // namespace

bool esc_keeps_whole(const Triangle& t) {
    const Vec3 e1 = t.v1 - t.v0, e2 = t.v2 - t.v0;
    return glm::length(glm::cross(e1, e2)) <= kEscLineSine * glm::length(e1) * glm::length(e2);
}

float automatic_sa_max(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs) {
    const size_t n = refs.size();
    if (n == 0) return std::numeric_limits<float>::infinity();
    std::vector<float> ideal = ideal_areas(triangles, refs);
    const double ideal_sum = parallel::sum_in_order(n, 16 * 1024, [&](size_t i) { return double(ideal[i]); });
    const double box_sum = parallel::sum_in_order(n, 16 * 1024, [&](size_t i) { return double(refs[i].bounds().area()); });
    const double fill = box_sum > 0.0 ? ideal_sum / box_sum : 1.0;
    if (fill >= kEscMaxFillToSplit) return std::numeric_limits<float>::infinity();
    const auto sa_max = float(kIdealAreasPerPiece * median_of(ideal));
    return sa_max > 0.0f ? sa_max : std::numeric_limits<float>::infinity();  // most triangles degenerate
}

namespace {

// Each reference's pieces at `sa_max`, if they sum to at most `budget` (at least the references): counting stops
// once the sum passes it, so a far too small SA_max costs about the budget, not the pieces it would make.
bool count_pieces_within(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs, float sa_max,
                         uint64_t budget, std::vector<uint32_t>& pieces) {
    pieces.resize(refs.size());
    const uint64_t extra_budget = budget - std::min<uint64_t>(budget, refs.size());  // pieces beyond one a reference
    std::atomic<uint64_t> extra{0};
    parallel::for_each(refs.size(), kGrain, [&](size_t i) {
        if (extra.load(std::memory_order_relaxed) > extra_budget) return;
        const Triangle& t = triangles[refs[i].prim];
        const BBox box = refs[i].bounds();
        const bool whole = box.area() <= sa_max || esc_keeps_whole(t);
        pieces[i] = whole ? 1 : clip_until_small(t, box, sa_max, [](const BBox&) {});
        if (pieces[i] > 1) extra.fetch_add(pieces[i] - 1, std::memory_order_relaxed);
    });
    return extra.load() <= extra_budget;
}

// The first doubling of `sa_max` (2^0 included) whose pieces fit `budget` on a sample of the references, scaled.
// The sample is scattered by a multiplicative hash, not strided, which a scene's periodic order would fool.
int sampled_doubling(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs, float sa_max, uint64_t budget) {
    std::vector<PrimRef> sample(std::min(refs.size(), kSampledReferences));
    for (size_t j = 0; j < sample.size(); ++j) sample[j] = refs[(uint64_t(j) * 0x9E3779B97F4A7C15ull) % refs.size()];
    const double share = double(sample.size()) / double(refs.size());
    const auto sample_budget = uint64_t(std::min(double(budget) * share, 1e18));
    std::vector<uint32_t> ignored;
    int k = 0;
    while (!count_pieces_within(triangles, sample, std::ldexp(sa_max, k), sample_budget, ignored)) ++k;
    return k;
}

// A doubling of `sa_max` whose pieces fit `budget`, their counts in `pieces`: the sample's guess, raised until
// every reference fits. A failed count costs about the budget, so the sample keeps them few.
float fitting_sa_max(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs, float sa_max,
                     uint64_t budget, std::vector<uint32_t>& pieces) {
    for (int k = refs.size() > kSampledReferences ? sampled_doubling(triangles, refs, sa_max, budget) : 0;; ++k)
        if (count_pieces_within(triangles, refs, std::ldexp(sa_max, k), budget, pieces)) return std::ldexp(sa_max, k);
}

void check_sa_max(float sa_max) {
    if (!(sa_max > 0.0f)) throw std::invalid_argument("esc: SA_max must be > 0, got " + std::to_string(sa_max));
}

}  // namespace

uint64_t early_split_clip_count(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs, float sa_max) {
    check_sa_max(sa_max);
    std::vector<uint32_t> pieces;
    count_pieces_within(triangles, refs, sa_max, std::numeric_limits<uint64_t>::max(), pieces);
    return std::accumulate(pieces.begin(), pieces.end(), uint64_t{0});
}

std::vector<PrimRef> early_split_clip_refs(std::span<const Triangle> triangles, std::vector<PrimRef>&& refs, float sa_max,
                                           uint64_t max_references) {
    check_sa_max(sa_max);
    const size_t n = refs.size();
    std::vector<uint32_t> pieces;
    sa_max = fitting_sa_max(triangles, refs, sa_max, std::max<uint64_t>(max_references, n), pieces);
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

SaMax parse_sa_max(const std::string& text) {
    if (text == "auto") return {};
    const bool relative = text.ends_with("x");
    const std::string number = relative ? text.substr(0, text.size() - 1) : text;
    size_t used = 0;
    float value = 0.0f;
    try {
        value = std::stof(number, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    if (number.empty() || used != number.size() || !(value > 0.0f) || !std::isfinite(value))
        throw std::invalid_argument("SA_max '" + text + "': auto, a positive box area (12.5) or a positive multiple of "
                                    "the median ideal triangle area (8x)");
    return {relative ? SaMax::Unit::MedianIdealArea : SaMax::Unit::Absolute, value};
}

std::string sa_max_name(const SaMax& sa_max) {
    if (sa_max.unit == SaMax::Unit::Automatic) return "auto";
    char text[32];
    std::snprintf(text, sizeof text, "%g%s", double(sa_max.value), sa_max.unit == SaMax::Unit::MedianIdealArea ? "x" : "");
    return text;
}

std::vector<BuilderParam> esc_params() {
    return {{kEscSaMaxKey, "auto",
             "SA_max of early split clipping: auto, a box area (12.5) or a multiple of the median ideal triangle area (8x)",
             [](const std::string& text) { return sa_max_name(parse_sa_max(text)); }}};
}

SaMax esc_sa_max(const BuildSettings& settings) {
    const std::string* text = settings.params.find(kEscSaMaxKey);
    return text ? parse_sa_max(*text) : SaMax{};
}

float resolve_esc_area(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs, const SaMax& sa_max) {
    if (sa_max.unit == SaMax::Unit::Automatic) return automatic_sa_max(triangles, refs);
    if (!(sa_max.value > 0.0f) || !std::isfinite(sa_max.value))
        throw std::invalid_argument("esc: SA_max must be finite and > 0, got " + std::to_string(sa_max.value));
    if (sa_max.unit == SaMax::Unit::Absolute) return sa_max.value;
    std::vector<float> ideal = ideal_areas(triangles, refs);
    const double area = median_of(ideal);
    return area > 0.0 ? float(sa_max.value * area) : std::numeric_limits<float>::infinity();
}

Bvh build_esc(BuildInput&& input, const BuildSettings& settings) {
    auto clip = [&](std::span<const Triangle> triangles, std::vector<PrimRef>&& refs) {
        const float sa_max = resolve_esc_area(triangles, refs, esc_sa_max(settings));
        const auto cap = uint64_t(kMaxEscReferencesPerTriangle * double(refs.size()));
        return std::isfinite(sa_max) ? early_split_clip_refs(triangles, std::move(refs), sa_max, cap) : std::move(refs);
    };
    return build_after_split_pass(std::move(input), settings, clip, &build_binned_sah);
}

}  // namespace canopy
