// The pairwise sum of sample images: its bits do not depend on how the samples are split into runs (the ranks of
// a job, renderer/sample_sum.h).
#include "renderer/sample_sum.h"

#include <catch2/catch.hpp>

#include <random>

using namespace canopy;

namespace {

constexpr int kWidth = 4, kHeight = 2;

// Values over six orders of magnitude, so that float sums of them depend on their order.
std::vector<std::vector<float>> random_samples(uint32_t count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> mantissa(1.0f, 2.0f);
    std::uniform_int_distribution<int> exponent(-10, 10);
    std::vector<std::vector<float>> samples(count, std::vector<float>(kWidth * kHeight * 3));
    for (auto& sample : samples)
        for (float& v : sample) v = std::ldexp(mantissa(rng), exponent(rng));
    return samples;
}

// The tree of sample_sum.h written as its definition: a node sums its left then its right child, or is its left
// child when the right one holds no sample.
std::vector<float> tree_sum(const std::vector<std::vector<float>>& samples, uint64_t first, uint64_t size) {
    if (size == 1) return samples[first];
    std::vector<float> left = tree_sum(samples, first, size / 2);
    if (first + size / 2 >= samples.size()) return left;
    const std::vector<float> right = tree_sum(samples, first + size / 2, size / 2);
    for (size_t i = 0; i < left.size(); ++i) left[i] += right[i];
    return left;
}

std::vector<float> definition(const std::vector<std::vector<float>>& samples) {
    uint64_t size = 1;
    while (size < samples.size()) size *= 2;
    return tree_sum(samples, 0, size);
}

// Samples [0, count) split into runs at `cuts`, each run summed by its own instance, the runs' nodes pushed in
// order into one more: what rank 0 does with the ranks' shares.
std::vector<float> split_sum(const std::vector<std::vector<float>>& samples, const std::vector<uint32_t>& cuts) {
    const uint32_t count = uint32_t(samples.size());
    PairwiseImageSum total(count);
    uint32_t begin = 0;
    for (size_t run = 0; run <= cuts.size(); ++run) {
        const uint32_t end = run < cuts.size() ? cuts[run] : count;
        PairwiseImageSum share(count);
        for (uint32_t s = begin; s < end; ++s) share.push(s, 0, Image(kWidth, kHeight, samples[s]));
        for (PairwiseImageSum::Node& node : std::move(share).take_nodes()) total.push(node.first, node.level, std::move(node.sum));
        begin = end;
    }
    return std::move(std::move(total).root()).take_sums();
}

std::vector<float> in_order_sum(const std::vector<std::vector<float>>& samples) {
    std::vector<float> sum(samples[0].size(), 0.0f);
    for (const auto& sample : samples)
        for (size_t i = 0; i < sum.size(); ++i) sum[i] += sample[i];
    return sum;
}

}  // namespace

TEST_CASE("the pairwise sample sum is its tree's definition, bit for bit", "[render][distributed]") {
    for (uint32_t count = 1; count <= 70; ++count) {
        const auto samples = random_samples(count, count);
        REQUIRE(split_sum(samples, {}) == definition(samples));
    }
}

TEST_CASE("the pairwise sample sum gives the same bits however its samples are split", "[render][distributed]") {
    bool order_matters = false;  // the data can tell summation orders apart, or this test could not fail
    for (uint32_t count = 1; count <= 24; ++count) {
        const auto samples = random_samples(count, 100 + count);
        const std::vector<float> whole = split_sum(samples, {});
        order_matters = order_matters || whole != in_order_sum(samples);
        for (uint32_t a = 0; a <= count; ++a)
            for (uint32_t b = a; b <= count; ++b) {
                INFO("count " << count << ", runs split at " << a << " and " << b);
                REQUIRE(split_sum(samples, {a, b}) == whole);
            }
    }
    CHECK(order_matters);
}

TEST_CASE("a pairwise sample sum missing samples has no root", "[render][distributed]") {
    const auto samples = random_samples(5, 1);
    PairwiseImageSum sum(5);
    for (uint32_t s = 0; s < 4; ++s) sum.push(s, 0, Image(kWidth, kHeight, samples[s]));
    REQUIRE_THROWS_AS(std::move(sum).root(), std::logic_error);
}
