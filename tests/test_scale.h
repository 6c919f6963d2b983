#pragma once
// CANOPY_TEST_SCALE, the one setting that shrinks the heaviest tests: the brute-force oracles' rays and scenes, the
// thread-determinism builds and every builder's structural checks. A CMake cache variable, 1 by default; the
// sanitizer presets (debug, tsan) set 0.1, because ASan and TSan slow these tests 10 to 50 times (a single oracle
// test ran 22 minutes under ASan). Scaled down, every test still runs every builder and kernel, on fewer rays and
// triangles: no test is skipped for its size.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>

namespace canopy::test {

inline constexpr double kTestScale = CANOPY_TEST_SCALE;
static_assert(kTestScale > 0.0 && kTestScale <= 1.0, "CANOPY_TEST_SCALE must be in (0, 1]");

// `count` scaled, and never below `at_least`: scenes keep enough triangles for trees many levels deep.
inline size_t scaled(size_t count, size_t at_least = 1) {
    return std::max(at_least, size_t(double(count) * kTestScale));
}

// "gen:NAME?tris=N&seed=S" with N scaled, at least 1000 triangles.
inline std::string scaled_spec(const std::string& generator, size_t triangles, uint64_t seed) {
    return "gen:" + generator + "?tris=" + std::to_string(scaled(triangles, 1000)) + "&seed=" + std::to_string(seed);
}

}  // namespace canopy::test
