#pragma once
// Hybrid packet traversal (Benthin, Wald, Woop, Ernst and Áfra 2012, "Combining Single and Packet-Ray Tracing for
// Arbitrary Ray Distributions on the Intel MIC Architecture", sec. 4): up to 16 rays (AVX-512; 8 with AVX2) of one
// direction octant walk a wide BVH together, a ray in each lane. A node's children are tested one after another against every active
// ray at once, with each ray's own slab data and far limit, so the node's cache lines are fetched once for the
// packet and the packet's rays hide each other's latency. Where fewer than kPacketSwitch rays remain on a subtree,
// each goes on alone in the single-ray kernel (sec. 4.2's switch). Each ray tests a node exactly as the single-ray
// kernel does (the same FMAs, maxima and minima in any order, integer ones being exact), so with robust
// watertight kernels a ray's closest hit is the single-ray kernel's (up to exact ties between triangles).
//
// A packet's leaves test one triangle against every lane at once (watertight_packet.h), and its rays' slab data is
// set up in lanes, not ray by ray: on diffuse rays a packet reaches a leaf with more rays than the leaf's blocks
// hold triangles, so a lane per ray keeps more lanes busy (docs/results.md#tracers-single-and-stream; where
// trace_packet's time goes: docs/results.md#traversal-kernels).
#include "kernels/packet_lanes.h"
#include "kernels/traverse.h"
#include "kernels/watertight_packet.h"

#include <immintrin.h>

#include <bit>
#include <new>
#include <span>

namespace canopy {

// Rays below which a packet's subtree is finished ray by ray: a packet pays where most of its lanes are busy, and
// 10 of 16 traced fastest of the thresholds tried (docs/results.md#traversal-kernels).
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

// Rays of one packet must share their near and far plane offsets (the octant the node test reads planes by), which
// SlabRay takes from the sign bits of the direction (-0 and NaNs included).
inline uint32_t octant(const Ray& ray) {
    return uint32_t(std::signbit(ray.dir.x)) | uint32_t(std::signbit(ray.dir.y)) << 1 | uint32_t(std::signbit(ray.dir.z)) << 2;
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
    alignas(sizeof(L::F)) float slab_lanes[9][kPacketRays];  // inv, near_add and far_add per axis, for lane_slab
    int near[3], far[3];
    alignas(TriangleTest) unsigned char tests[kPacketRays][sizeof(TriangleTest)];
    static_assert(std::is_trivially_destructible_v<TriangleTest>);
    // Leaves test a triangle against every lane at once where the test has a packet form (watertight_packet.h).
    static constexpr bool kPacketLeaves = std::is_same_v<TriangleTest, WatertightRay>;
    struct NoPacketTest {
        NoPacketTest(const TriangleTest*, uint32_t) {}
    };
    std::conditional_t<kPacketLeaves, WatertightPacket, NoPacketTest> packet_test;

    // `rays` share their direction octant.
    PacketRays(const Ray* rays, uint32_t count, const PlaneFrame& frame, bool robust)
        : packet_test(set_up_tests(rays, count), count) {
        alignas(sizeof(L::F)) float lanes[6][kPacketRays] = {};
        for (uint32_t r = 0; r < count; ++r) {
            for (int a = 0; a < 3; ++a) lanes[a][r] = rays[r].org[a], lanes[3 + a][r] = rays[r].dir[a];
            tmins[r] = kernel_tmin(rays[r]);
            tfar[r] = rays[r].tmax;
        }
        for (uint32_t r = count; r < kPacketRays; ++r) tmins[r] = tfar[r] = 0.0f;
        set_up_slabs(lanes, frame, robust);
        const SlabRay<N> first(rays[0], frame, robust);
        for (int a = 0; a < 3; ++a) near[a] = first.near[a], far[a] = first.far[a];
        tmin = L::load(tmins);
    }

    // Lane r's SlabRay, as SlabRay(ray, frame, robust) computes it, for the single-ray kernel.
    SlabRay<N> lane_slab(int r) const {
        SlabRay<N> slab;
        for (int a = 0; a < 3; ++a) {
            slab.inv_dir[a] = slab_lanes[a][r], slab.near_add[a] = slab_lanes[3 + a][r], slab.far_add[a] = slab_lanes[6 + a][r];
            slab.near[a] = near[a], slab.far[a] = far[a];
        }
        return slab;
    }

    const TriangleTest& test(int r) const { return *std::launder(reinterpret_cast<const TriangleTest*>(tests[r])); }

private:
    // SlabRay's arithmetic (traverse.h), operation for operation, on every lane at once.
    void set_up_slabs(const float (&lanes)[6][kPacketRays], const PlaneFrame& frame, bool robust) {
        const L::F sign = L::set1(-0.0f), largest = L::set1(std::numeric_limits<float>::max());
        const L::F infinity = L::set1(std::numeric_limits<float>::infinity());
        L::F org[3], abs_org[3];
        for (int a = 0; a < 3; ++a) {
            org[a] = L::sub(L::load(lanes[a]), L::set1(frame.origin[a]));
            abs_org[a] = L::and_not(sign, org[a]);
        }
        const L::F reach = L::mul(L::set1(kRobustPad), L::add(L::set1(frame.bound), L::max(abs_org[0], L::max(abs_org[1], abs_org[2]))));
        for (int a = 0; a < 3; ++a) {
            const L::F dir = L::load(lanes[3 + a]);
            const L::F magnitude = L::max(L::set1(kMinSlabDir), L::and_not(sign, dir));
            const L::F inv_dir = L::div(L::set1(1.0f), L::bit_or(magnitude, L::bit_and(sign, dir)));
            const L::F add = L::bit_xor(L::mul(org[a], inv_dir), sign);
            const L::F pad = robust ? L::mul(reach, L::and_not(sign, inv_dir)) : L::zero();
            const L::F lower = L::sub(add, pad), upper = L::add(add, pad);
            const L::M usable = L::mask_and(L::le(L::and_not(sign, lower), largest), L::le(L::and_not(sign, upper), largest));
            inv[a] = L::select(usable, inv_dir, L::zero());
            near_add[a] = L::select(usable, lower, L::bit_xor(infinity, sign));
            far_add[a] = L::select(usable, upper, infinity);
            L::store(slab_lanes[a], inv[a]);
            L::store(slab_lanes[3 + a], near_add[a]);
            L::store(slab_lanes[6 + a], far_add[a]);
        }
    }

    const TriangleTest* set_up_tests(const Ray* rays, uint32_t count) {
        for (uint32_t r = 0; r < count; ++r) new (tests[r]) TriangleTest(rays[r]);
        return &test(0);
    }
};

// A leaf against the lanes of `rays` (at least one); returns the lanes that recorded a hit in `hits`.
template <int N, class TriangleTest, class Counter>
[[gnu::always_inline]] inline uint32_t packet_leaf(const WideBvh<N>& bvh, const PacketEntry& e, uint32_t rays,
                                                   const PacketRays<N, TriangleTest>& p, Hit* hits, Counter& counter) {
    uint32_t found = 0;
    if constexpr (PacketRays<N, TriangleTest>::kPacketLeaves && N > 2) {
        for (uint32_t m = rays; m; m &= m - 1) counter.leaf(), counter.triangles(e.count);
        WatertightPacket::Nearest nearest{L::load(p.tfar), L::zero(), L::zero(), L::zero(), L::zero()};
        const L::M active = L::from_bits(rays);
        L::M took = L::from_bits(0);
        const uint32_t end = e.child + leaf_entries(N, e.count);
        for (uint32_t b = e.child; b < end; ++b) took = L::mask_or(took, p.packet_test.intersect_block(bvh.leaves[b], active, p.tmin, nearest));
        found = L::bits(took);
        if (!found) return 0;
        alignas(sizeof(L::F)) float t[kPacketRays], u[kPacketRays], v[kPacketRays], prim[kPacketRays];
        L::store(t, nearest.t);
        L::store(u, L::div(nearest.v, nearest.det));
        L::store(v, L::div(nearest.w, nearest.det));
        L::store(prim, nearest.prim);
        for (uint32_t m = found; m; m &= m - 1) {
            const int r = std::countr_zero(m);
            hits[r] = {t[r], u[r], v[r], std::bit_cast<uint32_t>(prim[r])};
        }
    } else {
        for (uint32_t m = rays; m; m &= m - 1) {
            const int r = std::countr_zero(m);
            if (intersect_leaf(bvh, StackEntry{e.child, e.count, e.tnear[r]}, p.test(r), p.tmins[r], hits[r], counter)) found |= 1u << r;
        }
    }
    return found;
}

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
// lane, each with its lanes and their distances, and starts fetching them: most are finished by rays on their own,
// whose first node is then on its way (docs/results.md#traversal-kernels).
template <int N, class TriangleTest>
[[gnu::always_inline]] inline PacketEntry* push_children(const WideBvh<N>& bvh, const WideNode<N>& node, uint32_t rays,
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
        prefetch(bvh.nodes.data(), bvh.leaves.data(), StackEntry{e.child, e.count, 0.0f});
        const auto key = [](const PacketEntry& entry) { return entry.tnear[std::countr_zero(entry.rays)]; };
        PacketEntry* j = sp++;
        for (; j > base && key(j[-1]) < key(e); --j) *j = j[-1];
        *j = e;
    }
    return sp;
}

template <Query Q, class TriangleTest, int N, class Counter>
void trace_packet(const WideBvh<N>& bvh, const Ray* rays, Hit* hits, uint32_t count, bool robust, Counter& counter) {
    for (uint32_t r = 0; r < count; ++r) {
        hits[r] = Hit{};
        hits[r].t = rays[r].tmax;
    }
    PacketRays<N, TriangleTest> p(rays, count, bvh.frame, robust);
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
                traverse_from<Q>(bvh, {e.child, e.count, e.tnear[r]}, p.lane_slab(r), p.tmins[r], hits[r], counter,
                                 [&](const StackEntry& leaf) { return intersect_leaf(bvh, leaf, test, p.tmins[r], hits[r], counter); });
                if (hits[r].found()) record_hit(r);
            }
            continue;
        }
        if (e.count == 0) {
            for (int i = std::popcount(rays_left); i > 0; --i) counter.inner();
            const WideNode<N>& node = bvh.nodes[e.child];
            prefetch_child_line(node);
            sp = push_children(bvh, node, rays_left, p, sp);
            continue;
        }
        for (uint32_t m = packet_leaf(bvh, e, rays_left, p, hits, counter); m; m &= m - 1) record_hit(std::countr_zero(m));
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
        size_t first = 0;
        for (size_t i = 1; i <= rays.size(); ++i) {
            if (i == rays.size() || i - first == size_t(detail::kPacketRays) || detail::octant(rays[i]) != detail::octant(rays[first])) {
                // A run too short for a packet (unsorted rays: most runs of one octant are a ray or two) goes ray by
                // ray, without the packet's set-up, as trace_packet would send it on at once.
                if (i - first < size_t(kPacketSwitch))
                    detail::trace_each<Q, Robust, TriangleTest>(bvh, rays.subspan(first, i - first), hits.subspan(first, i - first), counter);
                else
                    detail::trace_packet<Q, TriangleTest>(bvh, rays.data() + first, hits.data() + first, uint32_t(i - first), Robust,
                                                          counter);
                first = i;
            }
        }
#endif
    }
}

}  // namespace canopy
