// Casts one batch of rays read from a file and writes their closest hits: the C++ side of
// examples/python_vs_cpp.py, which gives Python's batch query the same rays and compares hits and times.
//   usage: batch_rays SCENE BUILDER KERNEL RAYS HITS [REPEATS]
// RAYS: n origins then n directions, x y z float32 each. HITS: t (float32), triangle (uint32), u, v (float32), n
// values each. The batch is traced REPEATS times (default 5); the fastest is printed.
#include <canopy/canopy.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <exception>
#include <fstream>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

std::vector<float> read_floats(const std::string& path) {
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    if (!in) throw std::invalid_argument(path + ": cannot open");
    std::vector<float> values(size_t(in.tellg()) / sizeof(float));
    in.seekg(0).read(reinterpret_cast<char*>(values.data()), std::streamsize(values.size() * sizeof(float)));
    if (values.empty() || values.size() % 6 != 0) throw std::invalid_argument(path + ": not n origins and n directions");
    return values;
}

template <class T>
void write(std::ofstream& out, const std::vector<T>& values) {
    out.write(reinterpret_cast<const char*>(values.data()), std::streamsize(values.size() * sizeof(T)));
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 6 || argc > 7) {
        std::fprintf(stderr, "usage: batch_rays SCENE BUILDER KERNEL RAYS HITS [REPEATS]\n");
        return 2;
    }
    try {
        const canopy::TriangleMesh mesh = canopy::load_triangles(argv[1]);
        const canopy::Accel accel({mesh.vertices, mesh.triangles}, {.builder = argv[2], .kernel = argv[3]});
        const std::vector<float> rays = read_floats(argv[4]);
        const size_t n = rays.size() / 6;
        const canopy::RayBatch batch{std::span(rays).first(3 * n), std::span(rays).subspan(3 * n), {}, {}};
        std::vector<float> t(n), u(n), v(n);
        std::vector<uint32_t> triangle(n);
        const int repeats = argc > 6 ? std::stoi(argv[6]) : 5;
        double best_ms = 1e300;
        for (int r = 0; r < repeats; ++r) {
            const auto start = std::chrono::steady_clock::now();
            accel.intersect(batch, {t, triangle, u, v, {}});
            best_ms = std::min(best_ms, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
        }
        std::ofstream out(argv[5], std::ios::binary);
        write(out, t), write(out, triangle), write(out, u), write(out, v);
        if (!out) throw std::invalid_argument(std::string(argv[5]) + ": cannot write");
        std::printf("batch_rays: %zu rays, %s %s, fastest of %d: %.2f ms (%.2f Mrays/s)\n", n, argv[2], argv[3], repeats,
                    best_ms, double(n) / best_ms / 1e3);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "batch_rays: %s\n", e.what());
        return 1;
    }
}
