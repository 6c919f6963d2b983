#pragma once
// Kernel choice at run time: which widths this build compiled (they need their instruction sets at compile
// time) and which the CPU runs. The default is the widest kernel available on both counts.
#include "accel/wide_bvh.h"

#include <stdexcept>
#include <string>
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

}  // namespace canopy
