#pragma once
// What the writers of wide trees share (the collapse, and lbvh's direct emission): the extent a subtree takes of
// the output arrays, streamed stores of assembled nodes and blocks, and triangles put into leaf lanes.
#include "accel/wide_bvh.h"

#include <immintrin.h>

#include <bit>

namespace canopy::wide_writing {

// What a wide subtree takes of the output arrays: wide nodes (its root included), leaf entries, and leaves.
struct Extent {
    uint32_t nodes, entries, leaves;

    Extent& operator+=(const Extent& o) {
        nodes += o.nodes, entries += o.entries, leaves += o.leaves;
        return *this;
    }
};

// Where a wide subtree's next node slot, leaf entry and leaf go.
using Cursor = Extent;

// Wide levels above the subtrees that are measured and written concurrently: 2^8 or 2^9 subtrees at any width.
template <int N>
constexpr uint32_t kTopDepth = 9 / std::bit_width(unsigned(N - 1));

// Index of the top-level node at `depth` reached by child choices `path` (base N digits), in level order.
template <int N>
uint32_t top_slot(uint32_t depth, uint32_t path) {
    uint32_t first = 0;
    for (uint32_t d = 0, level = 1; d < depth; ++d, level *= N) first += level;
    return first + path;
}

// Copies a node or leaf block to its array with non-temporal stores, in whole vectors where its size and alignment
// allow: traversal reads them only later, and a plain store would first fetch every line it writes. Such stores
// are weakly ordered: the thread that made them calls stream_fence() before others may read.
template <class Block>
void stream(Block* to, const Block& from) {
#if defined(__AVX__)
    if constexpr (sizeof(Block) % 32 == 0 && alignof(Block) >= 32) {
        for (size_t k = 0; k < sizeof(Block) / 32; ++k)
            _mm256_stream_si256(reinterpret_cast<__m256i*>(to) + k, _mm256_load_si256(reinterpret_cast<const __m256i*>(&from) + k));
        return;
    }
#endif
    if constexpr (sizeof(Block) % 16 == 0 && alignof(Block) >= 16) {
        for (size_t k = 0; k < sizeof(Block) / 16; ++k)
            _mm_stream_si128(reinterpret_cast<__m128i*>(to) + k, _mm_load_si128(reinterpret_cast<const __m128i*>(&from) + k));
        return;
    }
    *to = from;
}

inline void stream_fence() { _mm_sfence(); }

inline void put_triangle(LeafTriangle& out, uint32_t prim, const Triangle& t) { out = {t.v0, prim, t.v1, t.v2}; }

template <int W>
void put_triangle(TriangleBlock<W>& block, uint32_t lane, uint32_t prim, const Triangle& t) {
    const Vec3* vertices[3] = {&t.v0, &t.v1, &t.v2};
    for (int v = 0; v < 3; ++v)
        for (int a = 0; a < 3; ++a) block.v[v][a][lane] = (*vertices[v])[a];
    block.prim[lane] = prim;
}

// A block whose lanes hold no triangle: a degenerate triangle at the origin in each, never hit.
template <int W>
TriangleBlock<W> empty_block() {
    TriangleBlock<W> block;
    for (uint32_t lane = 0; lane < uint32_t(W); ++lane)
        put_triangle(block, lane, TriangleBlock<W>::kNone, Triangle{Vec3(0), Vec3(0), Vec3(0)});
    return block;
}

}  // namespace canopy::wide_writing
