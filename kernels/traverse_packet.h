#pragma once
// Hybrid packet traversal (Benthin, Wald, Woop, Ernst and Áfra 2012, "Combining Single and Packet-Ray Tracing for
// Arbitrary Ray Distributions on the Intel MIC Architecture", sec. 4): up to 16 rays (AVX-512; 8 with AVX2) of one
// direction octant walk a wide BVH together, a ray in each lane. A node's children are tested one after another against every active
// ray at once, with each ray's own slab data and far limit, so the node's cache lines are fetched once for the
// packet and the packet's rays hide each other's latency. Where fewer than kPacketSwitch rays remain on a subtree,
// each goes on alone in the single-ray kernel (sec. 4.2's switch). Each ray tests a node exactly as the single-ray
// kernel does (the same FMAs, maxima and minima in any order, integer ones being exact), so with robust
// watertight kernels a ray's closest hit is the single-ray kernel's (up to exact ties between triangles).
#include "kernels/traverse.h"

#include <immintrin.h>

#include <bit>
#include <new>
#include <span>

namespace canopy {

// Rays below which a packet's subtree is finished ray by ray: a packet pays where most of its lanes are busy. With
// 16-ray packets, stream frames against the single-path tracer's (one bench run each, 2 threads): crytek-sponza
// 0.87, 0.85, 0.80, 0.74, 0.80, 0.84 with 3, 6, 8, 10, 12, 14; conference 0.82, 0.81, 0.83 and sibenik 0.79, 0.79,
// 0.79 with 8, 10, 12 (the single-ray kernel on the same sorted batches: 0.92 to 1.01, 0.91 to 0.92, 0.88).
constexpr int kPacketSwitch = 10;

// Whether this build has the packet kernel (AVX2 lanes); without it, packets trace ray by ray.
constexpr bool packet_kernel_compiled() {
#if defined(__AVX2__) && defined(__FMA__)
    return true;
#else
    return false;
#endif
}

namespace detail {

// A batch ray by ray through the single-ray kernel of `tree` (flat or two-level).
template <Query Q, bool Robust, class TriangleTest, class Tree, class Counter>
void trace_each(const Tree& tree, std::span<const Ray> rays, std::span<Hit> hits, Counter& counter) {
    for (size_t i = 0; i < rays.size(); ++i) traverse<Q, Robust, TriangleTest>(tree, rays[i], hits[i], counter);
}

#if defined(__AVX2__) && defined(__FMA__)
// A packet's lanes: 16 rays in AVX-512 registers where the CPU has them, else 8 in AVX2 ones. Comparisons of slab
// distances by their bits as integers, as the single-ray node test makes them (intersect_children).
struct PacketLanes {
#if defined(__AVX512F__)
    static constexpr int kRays = 16;
    using F = __m512;
    static F load(const float* p) { return _mm512_load_ps(p); }
    static F broadcast(const float* p) { return _mm512_set1_ps(*p); }
    static void store(float* p, F a) { _mm512_store_ps(p, a); }
    static F fmadd(F a, F b, F c) { return _mm512_fmadd_ps(a, b, c); }
    // Zero-masked forms with a full mask: the unmasked intrinsics make GCC 12 warn of an undefined operand inside them.
    static F max_bits(F a, F b) { return _mm512_castsi512_ps(_mm512_maskz_max_epi32(0xffff, _mm512_castps_si512(a), _mm512_castps_si512(b))); }
    static F min_bits(F a, F b) { return _mm512_castsi512_ps(_mm512_maskz_min_epi32(0xffff, _mm512_castps_si512(a), _mm512_castps_si512(b))); }
    static uint32_t le_mask_bits(F a, F b) { return _mm512_cmple_epi32_mask(_mm512_castps_si512(a), _mm512_castps_si512(b)); }
    static uint32_t le_mask(F a, F b) { return _mm512_cmp_ps_mask(a, b, _CMP_LE_OQ); }
#else
    static constexpr int kRays = 8;
    using S = simd::Simd<8>;
    using F = __m256;
    static F load(const float* p) { return _mm256_load_ps(p); }
    static F broadcast(const float* p) { return _mm256_broadcast_ss(p); }
    static void store(float* p, F a) { _mm256_store_ps(p, a); }
    static F fmadd(F a, F b, F c) { return S::fmadd(a, b, c); }
    static F max_bits(F a, F b) { return S::max_bits(a, b); }
    static F min_bits(F a, F b) { return S::min_bits(a, b); }
    static uint32_t le_mask_bits(F a, F b) { return S::le_mask_bits(a, b); }
    static uint32_t le_mask(F a, F b) { return S::le_mask(a, b); }
#endif
};
#endif

// Rays of one packet must share their near and far plane offsets (the octant the node test reads planes by).
template <int N>
bool same_octant(const SlabRay<N>& a, const SlabRay<N>& b) {
    return a.near[0] == b.near[0] && a.near[1] == b.near[1] && a.near[2] == b.near[2];
}

#if defined(__AVX2__) && defined(__FMA__)

using L = PacketLanes;
constexpr int kPacketRays = L::kRays;

struct alignas(sizeof(L::F)) PacketEntry {
    float tnear[kPacketRays];  // per lane: the ray's entry distance to this node
    uint32_t child, count;     // as in WideNode: count 0 is an inner node
    uint32_t rays;             // lanes that reached it
};

// The packet's rays in lanes: slab data, intervals and triangle tests, set up once.
template <int N, class TriangleTest>
struct PacketRays {
    L::F inv[3], near_add[3], far_add[3], tmin;
    alignas(sizeof(L::F)) float tfar[kPacketRays];
    alignas(sizeof(L::F)) float tmins[kPacketRays];
    int near[3], far[3];
    alignas(TriangleTest) unsigned char tests[kPacketRays][sizeof(TriangleTest)];
    static_assert(std::is_trivially_destructible_v<TriangleTest>);

    PacketRays(const Ray* rays, const SlabRay<N>* slabs, const Hit* hits, uint32_t count) {
        alignas(sizeof(L::F)) float lanes[9][kPacketRays] = {};
        for (uint32_t r = 0; r < count; ++r) {
            for (int a = 0; a < 3; ++a) {
                lanes[a][r] = slabs[r].inv_dir[a];
                lanes[3 + a][r] = slabs[r].near_add[a];
                lanes[6 + a][r] = slabs[r].far_add[a];
            }
            tmins[r] = kernel_tmin(rays[r]);
            tfar[r] = hits[r].t;
            new (tests[r]) TriangleTest(rays[r]);
        }
        for (uint32_t r = count; r < kPacketRays; ++r) tmins[r] = tfar[r] = 0.0f;
        for (int a = 0; a < 3; ++a) {
            inv[a] = L::load(lanes[a]);
            near_add[a] = L::load(lanes[3 + a]);
            far_add[a] = L::load(lanes[6 + a]);
            near[a] = slabs[0].near[a], far[a] = slabs[0].far[a];
        }
        tmin = L::load(tmins);
    }

    const TriangleTest& test(int r) const { return *std::launder(reinterpret_cast<const TriangleTest*>(tests[r])); }
};

// Child `c` of `node` against every lane: the lanes whose ray enters it within its interval, and their entry
// distances, computed as intersect_children computes them for one ray.
template <int N, class TriangleTest>
[[gnu::always_inline]] inline uint32_t packet_child(const WideNode<N>& node, int c, const PacketRays<N, TriangleTest>& p,
                                                    L::F tfar, L::F& tnear) {
    L::F x[3], y[3];
    for (int a = 0; a < 3; ++a) {
        x[a] = L::fmadd(L::broadcast(node.planes + p.near[a] + c), p.inv[a], p.near_add[a]);
        y[a] = L::fmadd(L::broadcast(node.planes + p.far[a] + c), p.inv[a], p.far_add[a]);
    }
    const L::F t0 = L::max_bits(L::max_bits(x[1], p.tmin), L::max_bits(x[2], L::max_bits(x[0], p.tmin)));
    const L::F t1 = L::min_bits(L::min_bits(y[1], tfar), L::min_bits(y[2], L::min_bits(y[0], tfar)));
    tnear = t0;
    return L::le_mask_bits(t0, t1);
}

// Pushes the children of `node` that some active lane enters, far to near by the entry distance of the lowest such
// lane, each with its lanes and their distances.
template <int N, class TriangleTest>
[[gnu::always_inline]] inline PacketEntry* push_children(const WideNode<N>& node, uint32_t rays,
                                                         const PacketRays<N, TriangleTest>& p, PacketEntry* sp) {
    const L::F tfar = L::load(p.tfar);
    PacketEntry* const base = sp;
    for (int c = 0; c < N; ++c) {
        L::F tnear;
        const uint32_t lanes = packet_child(node, c, p, tfar, tnear) & rays;
        if (!lanes) continue;
        PacketEntry e;
        L::store(e.tnear, tnear);
        e.child = node.child[c], e.count = node.count[c], e.rays = lanes;
        const auto key = [](const PacketEntry& entry) { return entry.tnear[std::countr_zero(entry.rays)]; };
        PacketEntry* j = sp++;
        for (; j > base && key(j[-1]) < key(e); --j) *j = j[-1];
        *j = e;
    }
    return sp;
}

template <Query Q, class TriangleTest, int N, class Counter>
void trace_packet(const WideBvh<N>& bvh, const Ray* rays, Hit* hits, const SlabRay<N>* slabs, uint32_t count,
                  Counter& counter) {
    for (uint32_t r = 0; r < count; ++r) {
        hits[r] = Hit{};
        hits[r].t = rays[r].tmax;
    }
    PacketRays<N, TriangleTest> p(rays, slabs, hits, count);
    uint32_t done = 0;  // any hit: lanes that have one
    const auto record_hit = [&](int r) {  // after lane r recorded a hit
        p.tfar[r] = hits[r].t;
        if constexpr (Q == Query::Any) done |= 1u << r;
    };
    PacketEntry stack[kMaxBvhDepth * (N - 1) + 1];
    PacketEntry* sp = stack;
    *sp = PacketEntry{};
    L::store(sp->tnear, p.tmin);
    sp->child = 0, sp->count = 0, sp->rays = uint32_t((uint64_t(1) << count) - 1u);
    ++sp;
    while (sp != stack) {
        const PacketEntry e = *--sp;
        const uint32_t rays_left =
            e.rays & ~done & L::le_mask(L::load(e.tnear), L::load(p.tfar));
        if (!rays_left) continue;
        if (std::popcount(rays_left) < kPacketSwitch) {
            for (uint32_t m = rays_left; m; m &= m - 1) {
                const int r = std::countr_zero(m);
                const TriangleTest& test = p.test(r);
                traverse_from<Q>(bvh, {e.child, e.count, e.tnear[r]}, slabs[r], p.tmins[r], hits[r], counter,
                                 [&](const StackEntry& leaf) { return intersect_leaf(bvh, leaf, test, p.tmins[r], hits[r], counter); });
                if (hits[r].found()) record_hit(r);
            }
            continue;
        }
        if (e.count == 0) {
            for (int i = std::popcount(rays_left); i > 0; --i) counter.inner();
            const WideNode<N>& node = bvh.nodes[e.child];
            prefetch_child_line(node);
            sp = push_children(node, rays_left, p, sp);
            continue;
        }
        for (uint32_t m = rays_left; m; m &= m - 1) {
            const int r = std::countr_zero(m);
            if (intersect_leaf(bvh, StackEntry{e.child, e.count, e.tnear[r]}, p.test(r), p.tmins[r], hits[r], counter)) record_hit(r);
        }
    }
}

#endif

}  // namespace detail

// Closest or any hit of every ray, packets of up to kPacketRays consecutive rays of one octant at a time (so a batch
// sorted by octant, kernels/ray_order.h, forms full packets). Each ray's answer is the single-ray traverse()'s (see
// the top of this file for exact ties).
template <Query Q, bool Robust = true, class TriangleTest = WatertightRay, int N, class Counter = NoCount>
void traverse_packets(const WideBvh<N>& bvh, std::span<const Ray> rays, std::span<Hit> hits, Counter&& counter = {}) {
    if constexpr (N == 2 || !packet_kernel_compiled()) {
        detail::trace_each<Q, Robust, TriangleTest>(bvh, rays, hits, counter);
    } else {
#if defined(__AVX2__) && defined(__FMA__)
        if (bvh.nodes.empty()) return detail::trace_each<Q, Robust, TriangleTest>(bvh, rays, hits, counter);
        const float bound = plane_bound(bvh.bounds);
        detail::SlabRay<N> slabs[detail::kPacketRays];
        size_t first = 0;
        uint32_t count = 0;
        for (size_t i = 0; i <= rays.size(); ++i) {
            const bool end = i == rays.size();
            detail::SlabRay<N> slab;
            if (!end) slab = detail::SlabRay<N>(rays[i], bound, Robust);
            if (count > 0 && (end || count == detail::kPacketRays || !detail::same_octant(slab, slabs[0]))) {
                detail::trace_packet<Q, TriangleTest>(bvh, rays.data() + first, hits.data() + first, slabs, count, counter);
                first = i, count = 0;
            }
            if (!end) slabs[count++] = slab;
        }
#endif
    }
}

}  // namespace canopy
