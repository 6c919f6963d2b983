// random_rays: canopy's queries against Embree's on random rays inside a scene, closest hit and any hit, all threads,
// the fastest of REPEATS: the rays of a point-sampling, visibility or distance pipeline (what Python users trace),
// origins uniform in the scene's box and directions uniform on the sphere, so that neighbours share nothing.
// canopy through its public API (canopy::Accel: a batch call, and one call a ray on TBB's threads); Embree through
// its own (rtcIntersect1 / rtcOccluded1 a ray, rtcIntersect16 / rtcOccluded16 over 16 consecutive rays, and
// rtcIntersect1M / rtcOccluded1M over chunks, incoherent). Every query's answers are counted against canopy's batch.
//   random_rays SCENE [RAYS=1000000] [REPEATS=3] [BUILDER=binned] [KERNEL=auto]
#include "tools/embree_scene.h"

#include <canopy/canopy.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace {

constexpr size_t kChunk = 1024;  // rays a task, and a stream call's length
constexpr float kInf = std::numeric_limits<float>::infinity();

struct Rays {
    std::vector<float> origins, directions;  // x y z a ray
    size_t size() const { return origins.size() / 3; }
};

Rays random_rays(const canopy::FlatScene& flat, size_t n) {
    canopy::BBox box;
    for (const canopy::Triangle& t : flat.triangles) box.extend(canopy::BBox::of(t));
    std::mt19937_64 rng(42);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    Rays rays{std::vector<float>(3 * n), std::vector<float>(3 * n)};
    for (size_t i = 0; i < n; ++i) {
        const float z = 2.0f * unit(rng) - 1.0f, phi = 6.2831853f * unit(rng), r = std::sqrt(std::max(0.0f, 1.0f - z * z));
        for (int a = 0; a < 3; ++a) rays.origins[3 * i + a] = box.lower[a] + unit(rng) * (box.upper[a] - box.lower[a]);
        rays.directions[3 * i] = r * std::cos(phi), rays.directions[3 * i + 1] = r * std::sin(phi), rays.directions[3 * i + 2] = z;
    }
    return rays;
}

template <class Query>
double fastest_ms(int repeats, Query&& query) {
    double best = kInf;
    for (int r = 0; r < repeats; ++r) {
        const auto start = std::chrono::steady_clock::now();
        query();
        best = std::min(best, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
    }
    return best;
}

// `chunk`(first, count) over the rays in chunks, on TBB's threads.
template <class Chunk>
void in_chunks(size_t n, Chunk&& chunk) {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, kChunk), [&](const tbb::blocked_range<size_t>& r) {
        chunk(r.begin(), r.size());
    }, tbb::simple_partitioner());
}

RTCRay embree_ray(const Rays& rays, size_t i) {
    // RTCRay's members in declaration order: origin, tnear, direction, time, tfar, mask, id, flags.
    return RTCRay{rays.origins[3 * i], rays.origins[3 * i + 1], rays.origins[3 * i + 2], 0.0f, rays.directions[3 * i],
                  rays.directions[3 * i + 1], rays.directions[3 * i + 2], 0.0f, kInf, 0xffffffffu, 0, 0};
}

RTCIntersectContext context(RTCIntersectContextFlags flags) {
    RTCIntersectContext c;
    rtcInitIntersectContext(&c);
    c.flags = flags;
    return c;
}

// Embree's answers: whether each ray hit (closest) or is occluded (any), by each of its calls.
struct EmbreeQueries {
    RTCScene scene;
    const Rays& rays;

    void closest1(std::vector<char>& hit) const {
        in_chunks(rays.size(), [&](size_t first, size_t count) {
            RTCIntersectContext c = context(RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT);
            for (size_t i = first; i < first + count; ++i) {
                RTCRayHit rh{};
                rh.ray = embree_ray(rays, i);
                rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
                rtcIntersect1(scene, &c, &rh);
                hit[i] = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
            }
        });
    }
    void any1(std::vector<char>& hit) const {
        in_chunks(rays.size(), [&](size_t first, size_t count) {
            RTCIntersectContext c = context(RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT);
            for (size_t i = first; i < first + count; ++i) {
                RTCRay ray = embree_ray(rays, i);
                rtcOccluded1(scene, &c, &ray);
                hit[i] = ray.tfar < 0.0f;
            }
        });
    }
    void closest16(std::vector<char>& hit) const {
        in_packets([&](RTCIntersectContext& c, const int* valid, size_t p, size_t end) {
            alignas(64) RTCRayHit16 rh;
            fill16(rh.ray, p, end);
            for (int k = 0; k < 16; ++k) rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect16(valid, scene, &c, &rh);
            for (size_t k = 0; k < 16 && p + k < end; ++k) hit[p + k] = rh.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID;
        });
    }
    void any16(std::vector<char>& hit) const {
        in_packets([&](RTCIntersectContext& c, const int* valid, size_t p, size_t end) {
            alignas(64) RTCRay16 ray;
            fill16(ray, p, end);
            rtcOccluded16(valid, scene, &c, &ray);
            for (size_t k = 0; k < 16 && p + k < end; ++k) hit[p + k] = ray.tfar[k] < 0.0f;
        });
    }
    void closest1m(std::vector<char>& hit) const {
        in_chunks(rays.size(), [&](size_t first, size_t count) {
            RTCIntersectContext c = context(RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT);
            std::unique_ptr<RTCRayHit[]> rh(new RTCRayHit[count]());
            for (size_t k = 0; k < count; ++k) rh[k].ray = embree_ray(rays, first + k), rh[k].hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1M(scene, &c, rh.get(), unsigned(count), sizeof(RTCRayHit));
            for (size_t k = 0; k < count; ++k) hit[first + k] = rh[k].hit.geomID != RTC_INVALID_GEOMETRY_ID;
        });
    }
    void any1m(std::vector<char>& hit) const {
        in_chunks(rays.size(), [&](size_t first, size_t count) {
            RTCIntersectContext c = context(RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT);
            std::unique_ptr<RTCRay[]> ray(new RTCRay[count]);
            for (size_t k = 0; k < count; ++k) ray[k] = embree_ray(rays, first + k);
            rtcOccluded1M(scene, &c, ray.get(), unsigned(count), sizeof(RTCRay));
            for (size_t k = 0; k < count; ++k) hit[first + k] = ray[k].tfar < 0.0f;
        });
    }

private:
    // `packet`(context, valid, first ray, end of the chunk) for each 16 consecutive rays, on TBB's threads.
    template <class Packet>
    void in_packets(Packet&& packet) const {
        in_chunks(rays.size(), [&](size_t first, size_t count) {
            RTCIntersectContext c = context(RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT);
            for (size_t p = first; p < first + count; p += 16) {
                alignas(64) int valid[16];
                for (size_t k = 0; k < 16; ++k) valid[k] = p + k < first + count ? -1 : 0;
                packet(c, valid, p, first + count);
            }
        });
    }

    template <class Ray16>
    void fill16(Ray16& r, size_t p, size_t end) const {
        for (size_t k = 0; k < 16; ++k) {
            const size_t i = std::min(p + k, end - 1);
            r.org_x[k] = rays.origins[3 * i], r.org_y[k] = rays.origins[3 * i + 1], r.org_z[k] = rays.origins[3 * i + 2];
            r.dir_x[k] = rays.directions[3 * i], r.dir_y[k] = rays.directions[3 * i + 1], r.dir_z[k] = rays.directions[3 * i + 2];
            r.tnear[k] = 0.0f, r.tfar[k] = kInf, r.time[k] = 0.0f, r.mask[k] = 0xffffffffu, r.id[k] = 0, r.flags[k] = 0;
        }
    }
};

size_t differences(const std::vector<char>& a, const std::vector<char>& b) {
    size_t n = 0;
    for (size_t i = 0; i < a.size(); ++i) n += (a[i] != 0) != (b[i] != 0);
    return n;
}

struct Row {
    std::string name;
    double closest_ms, any_ms;
    size_t closest_differ, any_differ;
};

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2 || argc > 6) {
        std::fprintf(stderr, "usage: random_rays SCENE [RAYS=1000000] [REPEATS=3] [BUILDER=binned] [KERNEL=auto]\n");
        return 2;
    }
    try {
        const canopy::FlatScene flat = canopy::flatten(canopy::load_scene(argv[1]));
        const size_t n = argc > 2 ? std::stoul(argv[2]) : 1000000;
        const int repeats = argc > 3 ? std::stoi(argv[3]) : 3;
        std::vector<uint32_t> indices(3 * flat.triangles.size());
        for (uint32_t i = 0; i < indices.size(); ++i) indices[i] = i;
        const std::span<const float> vertices(reinterpret_cast<const float*>(flat.triangles.data()), 9 * flat.triangles.size());
        const canopy::Accel accel({vertices, indices}, {.builder = argc > 4 ? argv[4] : "binned", .kernel = argc > 5 ? argv[5] : "auto"});
        const canopy::tools::EmbreeScene embree(flat, 0);
        const Rays rays = random_rays(flat, n);

        // canopy's batch: the reference every other query's answers are counted against.
        const canopy::RayBatch batch{rays.origins, rays.directions, {}, {}};
        std::vector<float> t(n);
        std::unique_ptr<bool[]> occluded(new bool[n]);
        std::vector<char> closest(n), any(n), got(n);
        std::vector<Row> rows;
        Row row{"canopy batch", fastest_ms(repeats, [&] { accel.intersect(batch, {t, {}, {}, {}, {}}); }),
                fastest_ms(repeats, [&] { accel.occluded(batch, {occluded.get(), n}); }), 0, 0};
        for (size_t i = 0; i < n; ++i) closest[i] = std::isfinite(t[i]), any[i] = occluded[i];
        row.any_differ = differences(closest, any);
        rows.push_back(row);

        const auto origin = [&](size_t i) { return std::array<float, 3>{rays.origins[3 * i], rays.origins[3 * i + 1], rays.origins[3 * i + 2]}; };
        const auto direction = [&](size_t i) {
            return std::array<float, 3>{rays.directions[3 * i], rays.directions[3 * i + 1], rays.directions[3 * i + 2]};
        };
        row = {"canopy ray by ray", 0, 0, 0, 0};
        row.closest_ms = fastest_ms(repeats, [&] {
            in_chunks(n, [&](size_t first, size_t count) {
                for (size_t i = first; i < first + count; ++i) got[i] = std::isfinite(accel.intersect(origin(i), direction(i)).t);
            });
        });
        row.closest_differ = differences(closest, got);
        row.any_ms = fastest_ms(repeats, [&] {
            in_chunks(n, [&](size_t first, size_t count) {
                for (size_t i = first; i < first + count; ++i) got[i] = accel.occluded(origin(i), direction(i));
            });
        });
        row.any_differ = differences(closest, got);
        rows.push_back(row);

        const EmbreeQueries e{embree.scene(), rays};
        const auto embree_row = [&](const char* name, void (EmbreeQueries::*closest_query)(std::vector<char>&) const,
                                    void (EmbreeQueries::*any_query)(std::vector<char>&) const) {
            Row r{name, fastest_ms(repeats, [&] { (e.*closest_query)(got); }), 0, differences(closest, got), 0};
            r.any_ms = fastest_ms(repeats, [&] { (e.*any_query)(got); });
            r.any_differ = differences(closest, got);
            rows.push_back(r);
        };
        embree_row("Embree 1 (rtcIntersect1, rtcOccluded1)", &EmbreeQueries::closest1, &EmbreeQueries::any1);
        embree_row("Embree 16 (rtcIntersect16, rtcOccluded16)", &EmbreeQueries::closest16, &EmbreeQueries::any16);
        embree_row("Embree 1M (rtcIntersect1M, rtcOccluded1M)", &EmbreeQueries::closest1m, &EmbreeQueries::any1m);

        size_t hits = 0;
        for (char c : closest) hits += c;
        std::printf("random_rays: %zu rays inside %s (%zu triangles), %zu hit; canopy %s %s; fastest of %d, all threads\n",
                    n, argv[1], flat.triangles.size(), hits, accel.stats().builder.c_str(), accel.stats().kernel.c_str(), repeats);
        std::printf("| query | closest hit ms | any hit ms | any / closest | answers that differ (closest, any) |\n|---|---|---|---|---|\n");
        for (const Row& r : rows)
            std::printf("| %s | %.2f | %.2f | %.3f | %zu, %zu |\n", r.name.c_str(), r.closest_ms, r.any_ms, r.any_ms / r.closest_ms,
                        r.closest_differ, r.any_differ);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "random_rays: %s\n", e.what());
        return 1;
    }
}
