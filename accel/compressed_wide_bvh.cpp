#include "accel/compressed_wide_bvh.h"

#include "accel/parallel.h"

#include <cmath>
#include <limits>
#include <stdexcept>

namespace canopy {

// x / 2^e is exact in double for every float x and the exponents used here, and so are its floor or ceiling and
// their difference from the origin's step (integers below 2^25): x - origin itself could round.
uint8_t QuantisedAxis::quantise_lower(float x) const {
    return uint8_t(std::clamp(std::floor(std::ldexp(double(x), -exponent)) - first_step, 0.0, 255.0));
}
uint8_t QuantisedAxis::quantise_upper(float x) const {
    return uint8_t(std::clamp(std::ceil(std::ldexp(double(x), -exponent)) - first_step, 0.0, 255.0));
}

// The smallest exponent e such that [lower, upper] spans at most 255 steps of 2^e from a multiple of 2^e, and
// every multiple of 2^e up to |lower|, |upper| plus 256 steps is a float: with M = max(|lower|, |upper|) < 2^x,
// e >= x - 23 keeps those multiples below 2^(e + 24), where floats are spaced 2^e or closer. Then origin + q 2^e
// is a float for every byte q, and the kernels' FMA decoding it rounds nothing.
QuantisedAxis quantise_axis(float lower, float upper) {
    int x = 0;
    std::frexp(std::max(std::abs(lower), std::abs(upper)), &x);
    int e = std::max(x - 23, -149);  // 2^-149: the smallest float step
    for (;; ++e) {
        const double k0 = std::floor(std::ldexp(double(lower), -e)), k1 = std::ceil(std::ldexp(double(upper), -e));
        if (k1 - k0 <= 255.0) {
            const double top = std::ldexp(k0 + 255.0, e);
            if (e > 127 || std::abs(top) > double(std::numeric_limits<float>::max()))
                throw std::range_error("compressed layout: a node's planes reach beyond the float range");
            return {float(std::ldexp(k0, e)), float(std::ldexp(1.0, e)), e, k0};
        }
    }
}

template <int N>
CompressedNode<N> compress_node(const WideNode<N>& node) {
    CompressedNode<N> out{};
    for (int i = 0; i < N; ++i) {
        out.child[i] = node.child[i];
        if (node.is_empty(i)) continue;
        if (node.count[i] > std::numeric_limits<uint16_t>::max())
            throw std::length_error("compressed layout: a leaf of " + std::to_string(node.count[i]) +
                                    " triangles, more than a node's 16-bit count holds");
        out.count[i] = uint16_t(node.count[i]);
        out.valid |= uint8_t(1u << i);
    }
    for (int a = 0; a < 3; ++a) {
        float lower = std::numeric_limits<float>::infinity(), upper = -lower;
        for (int i = 0; i < N; ++i)
            if (!node.is_empty(i)) lower = std::min(lower, node.lower(a, i)), upper = std::max(upper, node.upper(a, i));
        const QuantisedAxis axis = quantise_axis(lower, upper);
        out.origin[a] = axis.origin, out.scale[a] = axis.scale;
        for (int i = 0; i < N; ++i) {
            const bool empty = node.is_empty(i);  // an inverted box, as in WideNode
            out.q[a * N + i] = empty ? 255 : axis.quantise_lower(node.lower(a, i));
            out.q[(3 + a) * N + i] = empty ? 0 : axis.quantise_upper(node.upper(a, i));
        }
    }
    return out;
}

template <int N>
CompressedWideBvh<N> compress(WideBvh<N>&& bvh) {
    CompressedWideBvh<N> out;
    out.nodes.resize(bvh.nodes.size());
    parallel::for_each(bvh.nodes.size(), 4096, [&](size_t n) { out.nodes[n] = compress_node(bvh.nodes[n]); });
    out.leaves = std::move(bvh.leaves);
    out.bounds = bvh.bounds;
    out.frame = bvh.frame;
    for (const CompressedNode<N>& node : out.nodes)
        for (int i = 0; i < N; ++i)
            if (!node.is_empty(i))
                for (int a = 0; a < 3; ++a)
                    out.frame.bound = std::max({out.frame.bound, std::abs(node.lower(a, i)), std::abs(node.upper(a, i))});
    return out;
}

template <int N>
WideBvh<N> decompress(const CompressedWideBvh<N>& bvh) {
    WideBvh<N> out;
    out.nodes.resize(bvh.nodes.size());
    for (size_t n = 0; n < bvh.nodes.size(); ++n) {
        const CompressedNode<N>& from = bvh.nodes[n];
        WideNode<N>& to = out.nodes[n];
        for (int i = 0; i < N; ++i) {
            to.child[i] = from.is_empty(i) ? WideNode<N>::kEmpty : from.child[i];
            to.count[i] = from.count[i];
            for (int a = 0; a < 3; ++a) {
                to.lower(a, i) = from.is_empty(i) ? std::numeric_limits<float>::infinity() : from.lower(a, i);
                to.upper(a, i) = from.is_empty(i) ? -std::numeric_limits<float>::infinity() : from.upper(a, i);
            }
        }
    }
    out.leaves.assign(bvh.leaves.begin(), bvh.leaves.end());
    out.bounds = bvh.bounds;
    out.frame = bvh.frame;
    return out;
}

NodeLayout parse_node_layout(const std::string& name) {
    if (name == "standard") return NodeLayout::Standard;
    if (name == "compressed") return NodeLayout::Compressed;
    throw std::invalid_argument("unknown layout '" + name + "' (known: standard, compressed)");
}

template CompressedNode<8> compress_node<8>(const WideNode<8>&);
template CompressedWideBvh<8> compress<8>(WideBvh<8>&&);
template WideBvh<8> decompress<8>(const CompressedWideBvh<8>&);

}  // namespace canopy
