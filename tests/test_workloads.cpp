// The rays a frame traces besides the protocol's diffuse paths (--workload camera, ao, nee): their images against
// what the scene's light gives analytically, nee against diffuse, every tracer against brute force and against the
// single-ray tracer, and Embree's rows against canopy's.
#include "oracle.h"
#include "experiments/embree_accelerator.h"
#include "renderer/frames.h"

#include <cmath>

using namespace canopy;
using namespace canopy::test;

namespace {

FlatScene with_bounds(FlatScene flat, const Vec3& kd = Vec3(0.8f)) {
    flat.materials = {{"grey", kd, Vec3(0.0f)}};
    flat.material.assign(flat.triangles.size(), 0);
    for (const Triangle& t : flat.triangles) flat.bounds.extend(BBox::of(t));
    return flat;
}

// A square floor at y = 0, 2 * half wide, facing +y, under the open sky.
FlatScene floor_under_sky(float half) {
    FlatScene flat;
    const Vec3 a(-half, 0, -half), b(half, 0, -half), c(half, 0, half), d(-half, 0, half);
    flat.triangles = {{a, c, b}, {a, d, c}};
    return with_bounds(flat);
}

// The inside of the cube [-1, 1]^3, closed on every side.
FlatScene closed_room() {
    FlatScene flat;
    flat.triangles = cube_inside();
    return with_bounds(flat);
}

// A box open towards +z (the camera's side) with a square lamp under its ceiling: the Cornell box's light paths.
FlatScene lit_box() {
    FlatScene flat = closed_room();
    flat.triangles.erase(flat.triangles.begin() + 2, flat.triangles.begin() + 4);  // the +z face
    const Vec3 a(-0.3f, 0.98f, -0.3f), b(0.3f, 0.98f, -0.3f), c(0.3f, 0.98f, 0.3f), d(-0.3f, 0.98f, 0.3f);
    flat.triangles.push_back({a, b, c});
    flat.triangles.push_back({a, c, d});
    flat.materials = {{"wall", Vec3(0.7f), Vec3(0.0f)}, {"lamp", Vec3(0.5f), Vec3(12.0f, 11.0f, 9.0f)}};
    flat.material.assign(flat.triangles.size(), 0);
    flat.material[flat.triangles.size() - 2] = flat.material[flat.triangles.size() - 1] = 1;
    flat.has_emitters = true;
    return flat;
}

FrameSettings settings_of(Workload workload, int w, int h, int bounces = 8) {
    FrameSettings s;
    s.width = w, s.height = h, s.max_bounces = bounces, s.workload = workload;
    return s;
}

struct Frame {
    std::vector<float> pixels;  // rgb, the mean over the frames
    uint64_t rays = 0;
    double mean = 0;
};

// Frames 0, 1, ... of a tracer (through render_frame) or of an accelerator (through render, the tracer it names).
template <class TracerOrAccelerator>
Frame render_with(const TracerOrAccelerator& what, const FlatScene& flat, const FrameSettings& s, const Camera& camera, int frames = 1) {
    const ShadingScene shading{flat, s};
    const PinholeCamera pinhole(camera, s.width, s.height);
    Image image(s.width, s.height);
    Frame f;
    for (int k = 0; k < frames; ++k) {
        if constexpr (std::is_base_of_v<Accelerator, TracerOrAccelerator>) f.rays += render(what, shading, pinhole, uint32_t(k), image);
        else f.rays += render_frame(what, shading, pinhole, uint32_t(k), image);
    }
    f.pixels = image.average(frames);
    f.mean = image.mean(frames);
    return f;
}

std::unique_ptr<Accelerator> built(std::unique_ptr<Accelerator> accel) {
    accel->prepare();
    accel->build();
    return accel;
}

const Camera kLookingDown{{0, 3, 3}, {0, 0, 0}, {0, 1, 0}, 40.0f};
const Camera kInTheRoom{{0, 0, 0}, {0, 0, -1}, {0, 1, 0}, 60.0f};
const Camera kBeforeTheBox{{0, 0, 3.5f}, {0, 0, 0}, {0, 1, 0}, 50.0f};

}  // namespace

TEST_CASE("workloads are named on the command line, and an unknown name is refused", "[render][workload]") {
    for (Workload w : {Workload::Diffuse, Workload::Camera, Workload::Nee, Workload::Ao}) CHECK(parse_workload(workload_name(w)) == w);
    CHECK_THROWS_WITH(parse_workload("shadow"), Catch::Contains("unknown workload 'shadow'") && Catch::Contains("nee"));
}

TEST_CASE("camera: the albedo times the cosine to the ray, and the sky where the ray misses", "[render][workload]") {
    const FlatScene floor = floor_under_sky(2.0f);
    const FrameSettings s = settings_of(Workload::Camera, 8, 6);
    const Frame f = render_with(BruteForceTracer{floor.triangles}, floor, s, kLookingDown);
    CHECK(f.rays == 48u);
    const ShadingScene shading{floor, s};
    const PinholeCamera camera(kLookingDown, s.width, s.height);
    for (int y = 0; y < s.height; ++y)
        for (int x = 0; x < s.width; ++x) {
            Rng rng(uint64_t(y) * uint64_t(s.width) + uint64_t(x), 0);
            const float u = rng.next_float(), v = rng.next_float();
            const Ray ray = camera.generate(x, y, u, v);
            const Hit hit = brute_force_closest(floor.triangles, ray);
            const float expected = hit.found() ? 0.8f * std::abs(ray.dir.y) : 1.0f;
            CHECK(f.pixels[size_t(3 * (y * s.width + x))] == Approx(expected).epsilon(1e-5));
        }
}

TEST_CASE("ao: nothing above an open floor occludes, a closed room occludes everything farther than its walls", "[render][workload]") {
    const FlatScene floor = floor_under_sky(100.0f);
    FrameSettings s = settings_of(Workload::Ao, 8, 6);
    s.ao_rays = 7;
    const Frame open = render_with(BruteForceTracer{floor.triangles}, floor, s, kLookingDown);
    for (float p : open.pixels) CHECK(p == 1.0f);
    CHECK(open.rays == 48u * 8u);  // every camera ray hits the floor: 7 probes each

    const FlatScene room = closed_room();
    s.ao_length = 10.0f;
    const Frame closed = render_with(BruteForceTracer{room.triangles}, room, s, kInTheRoom);
    for (float p : closed.pixels) CHECK(p == 0.0f);
    s.ao_length = 1e-3f;  // shorter than any hit point's distance to another wall
    const Frame short_rays = render_with(BruteForceTracer{room.triangles}, room, s, kInTheRoom);
    for (float p : short_rays.pixels) CHECK(p == 1.0f);
    // The default length is a tenth of the scene box's diagonal.
    CHECK(ShadingScene{room, settings_of(Workload::Ao, 1, 1)}.ao_length == Approx(0.1f * std::sqrt(12.0f)));
}

TEST_CASE("nee: a floor under the sky and the sun reflects the albedo times both irradiances", "[render][workload]") {
    // Radiance from a Lambertian floor: albedo / pi x (the sky's pi + the sun's pi cos(theta)).
    const FlatScene floor = floor_under_sky(1e4f);
    const float expected = 0.8f * (1.0f + Lights::sun_direction().y);
    const Frame nee = render_with(BruteForceTracer{floor.triangles}, floor, settings_of(Workload::Nee, 8, 6, 1), kLookingDown, 16);
    for (size_t i = 0; i < nee.pixels.size(); ++i) CHECK(nee.pixels[i] == Approx(expected).epsilon(1e-3));
    // Without a bounce there is no light sample either, as under diffuse: the floor is black.
    const Frame last = render_with(BruteForceTracer{floor.triangles}, floor, settings_of(Workload::Nee, 8, 6, 0), kLookingDown);
    for (float p : last.pixels) CHECK(p == 0.0f);
}

TEST_CASE("lights: a sampled direction's pdf is the pdf a bounce that finds the same point is weighed with", "[render][workload]") {
    const FlatScene box = lit_box();
    const Lights emitters(box, true);
    CHECK_FALSE(emitters.has_sun());
    Rng rng(1, 2);
    const Vec3 p(0.1f, -0.5f, 0.2f);
    for (int k = 0; k < 1000; ++k) {
        const LightSample s = emitters.sample(p, rng.next_float(), rng.next_float(), rng.next_float());
        const Vec3 q = p + s.distance * s.direction;
        REQUIRE(q.y == Approx(0.98f).margin(1e-5));  // on the lamp
        CHECK(std::abs(q.x) <= 0.3f + 1e-5f);
        CHECK(std::abs(q.z) <= 0.3f + 1e-5f);
        CHECK(s.pdf == Approx(emitters.emitter_pdf(s.radiance, s.distance, std::abs(s.direction.y))).epsilon(1e-4));
        CHECK(s.radiance == Vec3(12.0f, 11.0f, 9.0f));
    }
    const Lights sun(box, false);
    CHECK(sun.has_sun());
    for (int k = 0; k < 1000; ++k) {
        const LightSample s = sun.sample(p, rng.next_float(), rng.next_float(), rng.next_float());
        CHECK(sun.in_sun(s.direction));
        CHECK(std::isinf(s.distance));
        CHECK(s.pdf == Approx(1.0f / Lights::sun_solid_angle()));
    }
    CHECK_FALSE(sun.in_sun(-Lights::sun_direction()));
}

TEST_CASE("nee converges to diffuse's image with the scene's emitters as lights, with less noise", "[render][workload]") {
    const FlatScene box = lit_box();
    const auto accel = built(make_canopy_accelerator(box, {}));
    constexpr int kFrames = 256, kW = 16, kH = 12;
    // Per pixel, the mean and variance of the frames' samples (the red channel), rendered one frame at a time.
    const auto statistics = [&](Workload w) {
        FrameSettings s = settings_of(w, kW, kH);
        s.material_albedo = true;
        const ShadingScene shading{box, s};
        const PinholeCamera camera(kBeforeTheBox, kW, kH);
        std::vector<double> sum(kW * kH), sum2(kW * kH);
        for (int f = 0; f < kFrames; ++f) {
            Image image(kW, kH);
            render(*accel, shading, camera, uint32_t(f), image);
            const std::vector<float> px = image.average(1);
            for (int i = 0; i < kW * kH; ++i) sum[i] += px[3 * i], sum2[i] += double(px[3 * i]) * px[3 * i];
        }
        double mean = 0, variance = 0;
        for (int i = 0; i < kW * kH; ++i) {
            const double m = sum[i] / kFrames;
            mean += m, variance += sum2[i] / kFrames - m * m;
        }
        return std::pair(mean / (kW * kH), variance / (kW * kH));
    };
    const auto [diffuse_mean, diffuse_variance] = statistics(Workload::Diffuse);
    const auto [nee_mean, nee_variance] = statistics(Workload::Nee);
    // The frame mean's standard error from the pixels' variances; the two estimates are independent.
    const double error = std::sqrt((diffuse_variance + nee_variance) / (kFrames * kW * kH));
    INFO("diffuse " << diffuse_mean << " (variance " << diffuse_variance << "), nee " << nee_mean << " (" << nee_variance << ")");
    CHECK(std::abs(nee_mean - diffuse_mean) < 5.0 * error);
    CHECK(nee_variance < 0.5 * diffuse_variance);
}

TEST_CASE("every workload through canopy's kernels answers as brute force does", "[render][workload]") {
    const Scene scene = load_scene("gen:box?tris=2000&seed=4");
    const FlatScene flat = flatten(scene);
    const Camera camera = scene_camera(scene, flat);
    for (Workload w : {Workload::Camera, Workload::Ao, Workload::Nee}) {
        FrameSettings s = settings_of(w, 24, 18);
        const Frame expected = render_with(BruteForceTracer{flat.triangles}, flat, s, camera);
        for (const char* kernel : {"bvh2", "bvh4", "bvh8"})
            for (const char* toplevel : {"flat", "two-level"}) {
                CanopyOptions options;
                options.kernel = kernel, options.toplevel = toplevel;
                const auto accel = built(make_canopy_accelerator(scene, flat, options));
                INFO(workload_name(w) << " " << kernel << " " << toplevel);
                const Frame got = render_with(*accel, flat, s, camera);
                CHECK(double(got.rays) == Approx(double(expected.rays)).epsilon(0.002));
                CHECK(got.mean == Approx(expected.mean).epsilon(0.01));
            }
        CanopyOptions kd;
        kd.builder = "kdtree";
        const auto accel = built(make_canopy_accelerator(scene, flat, kd));
        const Frame got = render_with(*accel, flat, s, camera);
        INFO(workload_name(w) << " kdtree");
        CHECK(double(got.rays) == Approx(double(expected.rays)).epsilon(0.002));
        CHECK(got.mean == Approx(expected.mean).epsilon(0.01));
    }
}

TEST_CASE("every workload: the stream tracer renders the single tracer's pixels", "[stream][workload]") {
    const Scene scene = load_scene("gen:box?tris=3000&seed=1");
    const FlatScene flat = flatten(scene);
    const Camera camera = scene_camera(scene, flat);
    for (const char* kernel : {"bvh2", "bvh8"}) {
        CanopyOptions options;
        options.kernel = kernel;
        const auto accel = built(make_canopy_accelerator(scene, flat, options));
        for (Workload w : {Workload::Camera, Workload::Ao, Workload::Nee}) {
            FrameSettings s = settings_of(w, 40, 30);
            const Frame single = render_with(*accel, flat, s, camera, 2);
            s.tracer = TracerKind::Stream, s.stream_batching = StreamBatching::Wavefront;
            for (uint32_t paths : {1u, 97u, 1u << 16}) {
                s.stream_paths = paths;
                INFO(workload_name(w) << " " << kernel << ", " << paths << " paths a batch");
                const Frame stream = render_with(*accel, flat, s, camera, 2);
                CHECK(stream.rays == single.rays);
                CHECK(stream.pixels == single.pixels);
            }
        }
    }
}

TEST_CASE("every workload: Embree's single and stream rows trace canopy's rays to canopy's image", "[render][workload][embree]") {
    const Scene scene = load_scene("gen:box?tris=3000&seed=1");
    const FlatScene flat = flatten(scene);
    const Camera camera = scene_camera(scene, flat);
    const auto ours = built(make_canopy_accelerator(flat, {}));
    const auto embree = built(make_embree_accelerator(flat, "medium", 0));
    for (Workload w : {Workload::Diffuse, Workload::Camera, Workload::Ao, Workload::Nee}) {
        FrameSettings s = settings_of(w, 64, 48);
        const Frame expected = render_with(*ours, flat, s, camera, 4);
        for (bool stream : {false, true})
            for (bool packets : {false, true}) {
                if (!stream && packets) continue;
                s.tracer = stream ? TracerKind::Stream : TracerKind::Single;
                s.stream_batching = StreamBatching::Wavefront, s.embree_packets = packets;
                INFO(workload_name(w) << (stream ? packets ? " stream/16" : " stream/1m" : " single"));
                const Frame got = render_with(*embree, flat, s, camera, 4);
                // Embree's intersector is not watertight and its point comes from t, so paths part after a bounce or
                // two: statistics, not bits, within what diffuse paths differ by here (1.3% rays, 1.3% mean a frame).
                CHECK(double(got.rays) == Approx(double(expected.rays)).epsilon(0.02));
                CHECK(got.mean == Approx(expected.mean).epsilon(0.02));
            }
    }
}
