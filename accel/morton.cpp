#include "accel/morton.h"

#include "accel/parallel.h"

#include <algorithm>
#include <array>
#include <utility>

namespace canopy {
namespace {

constexpr size_t kGrain = 16 * 1024;

// Spreads the low 21 bits of x to every third bit of a 63-bit code.
uint64_t spread_bits(uint64_t x) {
    x &= 0x1fffff;
    x = (x | x << 32) & 0x001f00000000ffffull;
    x = (x | x << 16) & 0x001f0000ff0000ffull;
    x = (x | x << 8) & 0x100f00f00f00f00full;
    x = (x | x << 4) & 0x10c30c30c30c30c3ull;
    x = (x | x << 2) & 0x1249249249249249ull;
    return x;
}

// The references' boxes and (doubled) centroids, in one pass.
struct Extents {
    BBox boxes, centroids;
};

std::vector<uint64_t> morton_codes(const std::vector<PrimRef>& refs, BBox& bounds) {
    const Extents extents = parallel::reduce(
        refs.size(), kGrain, Extents{},
        [&](size_t begin, size_t end) {
            Extents e;
            for (size_t i = begin; i < end; ++i) e.boxes.extend(refs[i].bounds()), e.centroids.extend(refs[i].center2());
            return e;
        },
        [](Extents a, const Extents& b) { return Extents{merge(a.boxes, b.boxes), merge(a.centroids, b.centroids)}; });
    bounds = extents.boxes;
    const BBox& centroids = extents.centroids;
    const Vec3 extent = centroids.extent();
    Vec3 scale;
    for (int a = 0; a < 3; ++a) scale[a] = extent[a] > 0 ? float((1u << 21) - 1) / extent[a] : 0.0f;
    std::vector<uint64_t> codes(refs.size());
    parallel::for_each(refs.size(), kGrain, [&](size_t i) {
        const Vec3 q = (refs[i].center2() - centroids.lower) * scale;
        codes[i] = spread_bits(uint64_t(q.x)) << 2 | spread_bits(uint64_t(q.y)) << 1 | spread_bits(uint64_t(q.z));
    });
    return codes;
}

// A sort key: the code's top 32 bits above the reference's index. Radix passes move 8 bytes per reference instead
// of a 12-byte (code, index) pair; a sort over these bits is bandwidth-bound.
constexpr int kKeyCodeBits = 32;
constexpr int kLowBits = 63 - kKeyCodeBits;  // code bits below the key's, told apart afterwards
constexpr int kDigitBits = 11;
constexpr uint32_t kDigits = 1u << kDigitBits;

// Orders a run of codes equal in their top kKeyCodeBits by whole code; equal codes keep index order, as they came
// in. Short runs by insertion, long ones (dense clusters of tiny triangles) by std::sort on (code, index).
void sort_run(uint64_t* codes, uint32_t* order, size_t n) {
    if (n <= 32) {
        for (size_t i = 1; i < n; ++i) {
            const uint64_t code = codes[i];
            const uint32_t index = order[i];
            size_t j = i;
            for (; j > 0 && codes[j - 1] > code; --j) codes[j] = codes[j - 1], order[j] = order[j - 1];
            codes[j] = code, order[j] = index;
        }
        return;
    }
    std::vector<std::pair<uint64_t, uint32_t>> run(n);
    for (size_t i = 0; i < n; ++i) run[i] = {codes[i], order[i]};
    std::sort(run.begin(), run.end());
    for (size_t i = 0; i < n; ++i) codes[i] = run[i].first, order[i] = run[i].second;
}

// Least-significant-digit radix sort of the keys by their code bits, 11 bits a pass, each pass a parallel
// histogram, a prefix sum per chunk and a parallel stable scatter. The index in the key's low bits then gives the
// order and the whole codes, and the runs still tied are sorted in place. Stable, so equal codes keep index order
// and the result does not depend on threads.
void radix_sort(std::vector<uint64_t>& codes, std::vector<uint32_t>& order) {
    const size_t n = codes.size();
    const size_t chunks = std::max<size_t>(1, std::min<size_t>(64, n / kGrain));
    auto chunk_begin = [&](size_t c) { return n * c / chunks; };
    std::vector<uint64_t> keys(n), next(n);
    parallel::for_each(n, kGrain, [&](size_t i) { keys[i] = codes[i] >> kLowBits << 32 | i; });
    std::vector<std::array<uint32_t, kDigits>> counts(chunks);
    for (int shift = 32; shift < 64; shift += kDigitBits) {
        auto digit = [shift](uint64_t key) { return uint32_t(key >> shift) & (kDigits - 1); };
        parallel::for_each(chunks, 1, [&](size_t c) {
            counts[c].fill(0);
            for (size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i) ++counts[c][digit(keys[i])];
        });
        uint32_t offset = 0;
        for (uint32_t d = 0; d < kDigits; ++d)
            for (size_t c = 0; c < chunks; ++c) offset += std::exchange(counts[c][d], offset);
        parallel::for_each(chunks, 1, [&](size_t c) {
            for (size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i) next[counts[c][digit(keys[i])]++] = keys[i];
        });
        keys.swap(next);
    }
    // The sorted codes and indices, and the runs tied in the key's code bits, each run handled by the chunk it
    // starts in.
    order.resize(n);
    std::vector<uint64_t>& sorted = next;
    parallel::for_each(n, kGrain, [&](size_t i) {
        order[i] = uint32_t(keys[i]);
        sorted[i] = codes[order[i]];
    });
    parallel::for_each(chunks, 1, [&](size_t c) {
        for (size_t i = chunk_begin(c); i < chunk_begin(c + 1);) {
            size_t end = i + 1;
            while (end < n && keys[end] >> 32 == keys[i] >> 32) ++end;
            if (i > 0 && keys[i - 1] >> 32 == keys[i] >> 32) {  // started in an earlier chunk
                i = end;
                continue;
            }
            if (end - i > 1) sort_run(&sorted[i], &order[i], end - i);
            i = end;
        }
    });
    codes.swap(sorted);
}

}  // namespace

MortonOrder sort_by_morton_code(const std::vector<PrimRef>& refs) {
    MortonOrder sorted;
    sorted.codes = morton_codes(refs, sorted.bounds);
    radix_sort(sorted.codes, sorted.order);
    return sorted;
}

}  // namespace canopy
