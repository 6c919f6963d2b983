// Recorded rays (canopy rays record, bench --rays): a frame's rays and hits as the live frame traces them, the .npy
// file's round trip and its refusals, and the replay's answers in every tracer.
#include "oracle.h"
#include "experiments/embree_accelerator.h"
#include "kernels/dispatch.h"
#include "renderer/frames.h"
#include "renderer/recorded_rays.h"

#include <bit>
#include <cstring>
#include <filesystem>
#include <fstream>

using namespace canopy;
using namespace canopy::test;

namespace {

// The live frame's own queries, recorded: the flat kernel's closest hit with the corners it hands shading, and its
// any hit, as render() calls them.
template <class Kernel>
struct LiveRecorder {
    const Kernel& kernel;
    std::vector<RecordedRay>& rays;
    bool closest(const Ray& ray, Hit& hit, Triangle& corners) const {
        const bool found = kernel.closest(ray, hit, corners);
        if (!found) hit = Hit{}, hit.t = ray.tmax;
        rays.push_back({ray, false, hit});
        return found;
    }
    bool occluded(const Ray& ray) const {
        Hit hit;
        const bool found = kernel.template query<Query::Any>(ray, hit);
        rays.push_back({ray, true, hit});
        return found;
    }
};

bool same_bits(const RecordedRay& a, const RecordedRay& b) {
    const auto bits = [](float f) { return std::bit_cast<uint32_t>(f); };
    for (int k = 0; k < 3; ++k)
        if (bits(a.ray.org[k]) != bits(b.ray.org[k]) || bits(a.ray.dir[k]) != bits(b.ray.dir[k])) return false;
    return bits(a.ray.tmin) == bits(b.ray.tmin) && bits(a.ray.tmax) == bits(b.ray.tmax) && a.any == b.any &&
           a.hit.prim == b.hit.prim && bits(a.hit.t) == bits(b.hit.t) && bits(a.hit.u) == bits(b.hit.u) && bits(a.hit.v) == bits(b.hit.v);
}

struct Recorded {
    Scene scene;
    FlatScene flat;
    std::unique_ptr<Accelerator> accel;
    FrameSettings settings;
    std::vector<RecordedRay> rays;
};

Recorded record(Workload workload) {
    Recorded r;
    r.scene = load_scene("gen:box?tris=3000&seed=1");
    r.flat = flatten(r.scene);
    r.accel = make_canopy_accelerator(r.scene, r.flat, {});
    r.accel->prepare();
    r.accel->build();
    r.settings.width = 40, r.settings.height = 30, r.settings.workload = workload;
    const PinholeCamera camera(scene_camera(r.scene, r.flat), r.settings.width, r.settings.height);
    r.rays = record_frame(*r.accel, ShadingScene{r.flat, r.settings}, camera, 1);
    return r;
}

std::string temporary(const std::string& name) { return (std::filesystem::temp_directory_path() / name).string(); }

}  // namespace

TEST_CASE("a recorded frame holds the live frame's rays and hits, bit for bit", "[rays]") {
    for (Workload w : {Workload::Diffuse, Workload::Camera, Workload::Ao, Workload::Nee}) {
        Recorded r = record(w);
        std::vector<RecordedRay> live;
        with_kernel(r.accel->bound_kernel(), [&]<class Kernel>(const Kernel& k) {
            if constexpr (requires(Hit& h, Triangle& c) { k.closest(Ray{}, h, c); }) {
                const LiveRecorder<Kernel> recorder{k, live};
                Image unused(r.settings.width, r.settings.height);
                uint64_t count = 0;
                const PinholeCamera camera(scene_camera(r.scene, r.flat), r.settings.width, r.settings.height);
                const ShadingScene shading{r.flat, r.settings};
                for (int y = 0; y < r.settings.height; ++y)
                    for (int x = 0; x < r.settings.width; ++x) trace_pixel(recorder, shading, camera, 1, x, y, unused, count);
            }
        }, [] {});
        INFO(workload_name(w));
        REQUIRE(live.size() == r.rays.size());
        size_t differ = 0, any = 0;
        for (size_t i = 0; i < live.size(); ++i) differ += !same_bits(live[i], r.rays[i]), any += r.rays[i].any;
        CHECK(differ == 0);
        CHECK((any > 0) == (w == Workload::Ao || w == Workload::Nee));
    }
}

TEST_CASE("a ray file reads back bit for bit, and bench's replay gives the recorded hits in every tracer", "[rays]") {
    const Recorded r = record(Workload::Nee);
    const std::string path = temporary("canopy_test_rays.npy");
    write_rays(path, r.rays);
    const std::vector<RecordedRay> back = read_rays(path);
    REQUIRE(back.size() == r.rays.size());
    for (size_t i = 0; i < back.size(); ++i) REQUIRE(same_bits(back[i], r.rays[i]));
    for (TracerKind tracer : {TracerKind::Single, TracerKind::Stream}) {
        FrameSettings settings;
        settings.tracer = tracer;
        std::vector<Hit> hits(back.size());
        replay(*r.accel, settings, back, hits);
        size_t differ = 0;
        for (size_t i = 0; i < back.size(); ++i) {
            const Hit& want = back[i].hit;
            differ += back[i].any ? hits[i].found() != want.found()
                                  : hits[i].prim != want.prim || std::bit_cast<uint32_t>(hits[i].t) != std::bit_cast<uint32_t>(want.t);
        }
        CHECK(differ == 0);
    }
    // Embree's replay agrees on all but rays at edges, which its intersector decides otherwise.
    auto embree = make_embree_accelerator(r.flat, "medium", 0);
    embree->prepare();
    embree->build();
    for (bool packets : {false, true}) {
        FrameSettings settings;
        settings.tracer = TracerKind::Stream, settings.embree_packets = packets;
        std::vector<Hit> hits(back.size());
        replay(*embree, settings, back, hits);
        size_t differ = 0;
        for (size_t i = 0; i < back.size(); ++i) differ += hits[i].found() != back[i].hit.found();
        CHECK(differ <= back.size() / 200);
    }
    std::filesystem::remove(path);
}

TEST_CASE("a file that is not a ray file is refused, naming the file and what is wrong", "[rays]") {
    const std::string path = temporary("canopy_test_bad_rays.npy");
    const Recorded r = record(Workload::Camera);
    write_rays(path, {r.rays.begin(), r.rays.begin() + 3});
    std::string good;
    {
        std::ifstream in(path, std::ios::binary);
        good.assign(std::istreambuf_iterator<char>(in), {});
    }
    const auto refused = [&](const std::string& bytes, const std::string& what) {
        std::ofstream(path, std::ios::binary) << bytes;
        CHECK_THROWS_WITH(read_rays(path), Catch::Contains(path) && Catch::Contains(what));
    };
    refused("not numpy", "no .npy magic string");
    refused(good.substr(0, good.size() - 5), "'shape' says 3 rays");
    std::string other_dtype = good;
    other_dtype.replace(other_dtype.find("'<u4'"), 5, "'<i4'");
    refused(other_dtype, "'descr'");
    std::string nan_ray = good;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    std::memcpy(nan_ray.data() + (good.size() - 3 * 49), &nan, 4);  // the first ray's org.x
    refused(nan_ray, "ray 0's 'org' or 'dir' is not finite");
    std::string backwards = good;
    const float tmin = 5.0f, tmax = 1.0f;
    std::memcpy(backwards.data() + (good.size() - 49) + 24, &tmin, 4);
    std::memcpy(backwards.data() + (good.size() - 49) + 28, &tmax, 4);
    refused(backwards, "ray 2's interval");
    CHECK_THROWS_WITH(read_rays(path + ".absent"), Catch::Contains("cannot open"));
    std::filesystem::remove(path);
}
