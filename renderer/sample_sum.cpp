#include "renderer/sample_sum.h"

#include "renderer/distributed.h"

#include <stdexcept>

namespace canopy {

void PairwiseImageSum::push(uint32_t first, uint32_t level, Image sum) {
    for (;;) {
        const uint64_t size = uint64_t(1) << level;
        if (first == 0 && size >= count_) break;  // the root
        if (((first >> level) & 1) == 0) {        // a left child
            if (first + size < count_) break;     // its right sibling is still to come
            ++level;                              // no sample right of it: the parent is this sum
            continue;
        }
        // A right child: its left sibling is on top when this instance summed it (another run's otherwise).
        if (nodes_.empty() || nodes_.back().first != first - size || nodes_.back().level != level) break;
        Node left = std::move(nodes_.back());
        nodes_.pop_back();
        left.sum += sum;
        sum = std::move(left.sum);
        first = left.first, ++level;
    }
    nodes_.push_back({first, level, std::move(sum)});
}

Image PairwiseImageSum::root() && {
    if (nodes_.size() != 1 || nodes_[0].first != 0 || (uint64_t(1) << nodes_[0].level) < count_)
        throw std::logic_error("a pairwise sum missing samples");
    return std::move(nodes_[0].sum);
}

namespace {

// A part's key: the subtree it sums.
uint64_t node_key(uint32_t first, uint32_t level) { return uint64_t(first) << 8 | level; }

}  // namespace

SampledImage render_samples(const Accelerator& accel, const ShadingScene& shading, const PinholeCamera& camera,
                            uint32_t first_frame, int spp, const std::function<void(float)>& progress) {
    const int width = shading.settings.width, height = shading.settings.height;
    const uint32_t count = uint32_t(spp), ranks = uint32_t(distributed::ranks()), rank = uint32_t(distributed::rank());
    const uint32_t begin = uint32_t(uint64_t(count) * rank / ranks), end = uint32_t(uint64_t(count) * (rank + 1) / ranks);
    PairwiseImageSum mine(count);
    uint64_t rays = 0;
    for (uint32_t s = begin; s < end; ++s) {
        const auto on_tile = [&](float f) { progress((float(s - begin) + f) / float(end - begin)); };
        Image sample(width, height);
        rays += render(accel, shading, camera, first_frame + s, sample,
                             progress ? std::function<void(float)>(on_tile) : std::function<void(float)>());
        mine.push(s, 0, std::move(sample));
    }
    std::vector<distributed::Part> parts;
    for (PairwiseImageSum::Node& node : std::move(mine).take_nodes())
        parts.push_back({node_key(node.first, node.level), std::move(node.sum).take_sums()});
    PairwiseImageSum total(count);
    distributed::gather_parts_to_root(std::move(parts), [&](distributed::Part&& part) {
        total.push(uint32_t(part.key >> 8), uint32_t(part.key & 0xff), Image(width, height, std::move(part.values)));
    });
    rays = distributed::sum_to_root(rays);
    return {distributed::is_root() ? std::move(total).root() : Image(0, 0), rays};
}

}  // namespace canopy
