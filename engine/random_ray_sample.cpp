#include "engine/random_ray_sample.h"

#include "engine/accelerator.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

namespace canopy {
namespace {

// Rays in blocks of kBlock, one block in `stride` traced: neighbouring rays are independent, so any block is as
// representative as a pixel tile, and a block fills the batch kernel's packets.
constexpr uint32_t kBlock = 64;

class RandomRaySample final : public WorkloadSample {
public:
    RandomRaySample(const FlatScene& flat, uint32_t rays, uint64_t seed) : hits_(rays) {
        BBox bounds{Vec3(0.0f), Vec3(0.0f)};
        if (!flat.triangles.empty()) bounds = BBox::of(flat.triangles[0]);
        for (const Triangle& t : flat.triangles) bounds.extend(BBox::of(t));
        rays_ = random_rays(bounds, rays, seed);
    }

    uint64_t pixels() const override { return rays_.size(); }
    double aspect() const override { return 1.0; }

    void trace(const Accelerator& tree, uint32_t stride) override {
        const uint32_t blocks = traced_blocks(stride);
        tbb::parallel_for(0u, blocks, [&](uint32_t k) {
            const size_t first = size_t(k) * stride * kBlock, count = std::min<size_t>(kBlock, rays_.size() - first);
            std::fill_n(hits_.begin() + first, count, Hit{});
            tree.trace_batch(Query::Closest, std::span(rays_).subspan(first, count), std::span(hits_).subspan(first, count));
        });
    }

    double share(uint32_t stride) const override {
        return rays_.empty() ? 0.0 : std::min(1.0, double(traced_blocks(stride)) * kBlock / double(rays_.size()));
    }

private:
    uint32_t traced_blocks(uint32_t stride) const {
        const uint64_t blocks = (rays_.size() + kBlock - 1) / kBlock;
        return uint32_t((blocks + stride - 1) / std::max<uint32_t>(stride, 1));
    }

    std::vector<Ray> rays_;
    std::vector<Hit> hits_;
};

}  // namespace

std::vector<Ray> random_rays(const BBox& box, size_t count, uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<Ray> rays(count);
    for (Ray& ray : rays) {
        const Vec3 s(unit(rng), unit(rng), unit(rng));
        const float z = 2.0f * unit(rng) - 1.0f, phi = 2.0f * std::numbers::pi_v<float> * unit(rng);
        const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
        ray.org = box.lower + s * (box.upper - box.lower);
        ray.dir = Vec3(r * std::cos(phi), r * std::sin(phi), z);
    }
    return rays;
}

std::shared_ptr<WorkloadSample> random_ray_sample(const FlatScene& flat, uint32_t rays, uint64_t seed) {
    return std::make_shared<RandomRaySample>(flat, rays, seed);
}

}  // namespace canopy
