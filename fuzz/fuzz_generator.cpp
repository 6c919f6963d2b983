// Generator specs, "gen:NAME?tris=N&seed=S": the input is the spec. Specs too large for the fuzz bound are
// refused before anything is generated, so the target also checks that the size bound comes first. An input
// without the "gen:" prefix gets it: load_scene would otherwise read it as a path.
#include "fuzz/fuzz_support.h"

// About 40 000 triangles: generating more per input would slow the fuzzer without reaching new code.
constexpr uint64_t kGeneratorBound = 16ull << 20;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace canopy::fuzz;
    const std::string_view input = as_text(data, size);
    load_and_flatten(input.starts_with("gen:") ? std::string(input) : "gen:" + std::string(input), kGeneratorBound);
    return 0;
}
