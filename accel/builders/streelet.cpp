#include "accel/builders/streelet.h"
#include "accel/split_pass.h"

#include "accel/builders/lbvh.h"
#include "accel/builders/presplit.h"
#include "accel/builders/treelet_restructuring.h"


namespace canopy {

// The quality-metrics paper runs STreelet with a 30% split quota in all but one scene.
constexpr float kStreeletSplitQuota = 0.3f;

Bvh build_streelet(BuildInput&& input, const BuildSettings& settings) {
    auto split = [](std::span<const Triangle> triangles, std::vector<PrimRef>&& refs) {
        return presplit_refs(triangles, std::move(refs), kStreeletSplitQuota);
    };
    auto lbvh_then_treelets = [](BuildInput&& pieces, const BuildSettings& s) {
        Bvh bvh = build_lbvh(std::move(pieces), s);
        bvh.one_ref_leaves.clear();
        optimise_treelets(bvh, s);
        return bvh;
    };
    return build_after_split_pass(std::move(input), settings, split, +lbvh_then_treelets);
}

}  // namespace canopy
