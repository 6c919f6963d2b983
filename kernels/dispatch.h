#pragma once
// Kernel choice at run time, in one place: which widths this build compiled (they need their instruction sets at
// compile time) and which the CPU runs, and the table that binds a built layout and the traversal's modes to the
// compiled kernel (with_kernel). The default width is the widest available on both counts.
#include "accel/two_level.h"
#include "accel/wide_bvh.h"
#include "kernels/kernel.h"

#include <stdexcept>
#include <string>
#include <variant>
#include <vector>

namespace canopy {

struct KernelInfo {
    const char* name;
    int width;
    const char* isa;  // what the CPU must have
};

inline const std::vector<KernelInfo>& kernel_infos() {
    static const std::vector<KernelInfo> kernels = {
        {"bvh2", 2, "x86-64 (scalar)"}, {"bvh4", 4, block_lanes(4) == 8 ? "SSE4.2, FMA and AVX2 (8-lane leaf tests)" : "SSE4.2 and FMA"}, {"bvh8", 8, "AVX2 and FMA"}};
    return kernels;
}

constexpr bool kernel_compiled(int width) {
#if defined(__SSE4_2__) && defined(__FMA__)
    constexpr bool sse = true;
#else
    constexpr bool sse = false;
#endif
#if defined(__AVX2__) && defined(__FMA__)
    constexpr bool avx = true;
#else
    constexpr bool avx = false;
#endif
    return width == 2 || (width == 4 && sse) || (width == 8 && avx);
}

inline bool cpu_runs(int width) {
    if (width == 2) return true;
    if (width == 4) {  // its leaves take AVX when the build has it (block_lanes)
        const bool leaves = block_lanes(4) == 4 || __builtin_cpu_supports("avx2");
        return __builtin_cpu_supports("sse4.2") && __builtin_cpu_supports("fma") && leaves;
    }
    return width == 8 && __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
}

// Width of the named kernel ("auto": the widest available). Throws std::invalid_argument for an unknown
// name, or a kernel that this build or this CPU cannot run, saying which.
inline int kernel_width(const std::string& name) {
    if (name == "auto") {
        int widest = 2;
        for (const KernelInfo& k : kernel_infos())
            if (kernel_compiled(k.width) && cpu_runs(k.width)) widest = k.width;
        return widest;
    }
    std::string known;
    for (const KernelInfo& k : kernel_infos()) {
        if (name == k.name) {
            if (!cpu_runs(k.width)) throw std::invalid_argument("kernel '" + name + "' needs " + k.isa + ", which this CPU lacks");
            if (!kernel_compiled(k.width))
                throw std::invalid_argument("kernel '" + name + "' needs " + k.isa + "; this build was compiled without it");
            return k.width;
        }
        known += std::string(known.empty() ? "" : ", ") + k.name;
    }
    throw std::invalid_argument("unknown kernel '" + name + "' (known: auto, " + known + ")");
}

inline std::string kernel_name(int width) { return "bvh" + std::to_string(width); }

// Every traversal layout a BVH accelerator builds.
using AnyLayout = std::variant<WideBvh<2>, WideBvh<4>, WideBvh<8>, CompressedWideBvh<8>, TwoLevelBvh<2>, TwoLevelBvh<4>,
                               TwoLevelBvh<8>>;

// The traversal's run-time choices, each a compile-time argument of the kernel.
struct KernelModes {
    bool robust = true;      // robust traversal (Ize 2013); false is the fast mode
    bool watertight = true;  // watertight intersection (Woop et al. 2013); false: Moller-Trumbore
};

template <class... Layouts>
using BvhKernelsOf = std::variant<std::monostate, BvhKernel<Layouts, true, WatertightRay>...,
                                  BvhKernel<Layouts, true, MollerTrumboreRay>..., BvhKernel<Layouts, false, WatertightRay>...,
                                  BvhKernel<Layouts, false, MollerTrumboreRay>..., KdKernel<WatertightRay>,
                                  KdKernel<MollerTrumboreRay>>;
// A built tree bound to its kernel; monostate for an accelerator whose queries go through another library.
using AnyKernel = BvhKernelsOf<WideBvh<2>, WideBvh<4>, WideBvh<8>, CompressedWideBvh<8>, TwoLevelBvh<2>, TwoLevelBvh<4>,
                               TwoLevelBvh<8>>;

template <class Kernel>
constexpr bool is_compiled_kernel = true;
template <class Layout, bool Robust, class Test>
constexpr bool is_compiled_kernel<BvhKernel<Layout, Robust, Test>> = kernel_compiled(Layout::kWidth);

// The kernel of `layout` in `modes`: each combination is its own compiled kernel.
inline AnyKernel make_kernel(const AnyLayout& layout, KernelModes modes) {
    return std::visit([&]<class Layout>(const Layout& bvh) -> AnyKernel {
        using W = WatertightRay;
        using M = MollerTrumboreRay;
        if (modes.robust) return modes.watertight ? AnyKernel(BvhKernel<Layout, true, W>{bvh}) : AnyKernel(BvhKernel<Layout, true, M>{bvh});
        return modes.watertight ? AnyKernel(BvhKernel<Layout, false, W>{bvh}) : AnyKernel(BvhKernel<Layout, false, M>{bvh});
    }, layout);
}
inline AnyKernel make_kernel(const KdTree& tree, KernelModes modes) {
    return modes.watertight ? AnyKernel(KdKernel<WatertightRay>{tree}) : AnyKernel(KdKernel<MollerTrumboreRay>{tree});
}

// Calls f(kernel) with the kernel's own type: the one dispatch every frame or batch pays. Widths this build did not
// compile never get here (kernel_width rejects them); `none` answers an accelerator without a kernel of canopy's.
template <class F, class None>
decltype(auto) with_kernel(const AnyKernel& kernel, F&& f, None&& none) {
    using Result = decltype(none());
    return std::visit([&]<class Kernel>(const Kernel& k) -> Result {
        if constexpr (std::is_same_v<Kernel, std::monostate>) {
            return none();
        } else if constexpr (is_compiled_kernel<Kernel>) {
            return f(k);
        } else {
            return none();
        }
    }, kernel);
}

}  // namespace canopy
