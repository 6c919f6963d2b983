// Intel Embree 3 as the reference accelerator: same flat triangles, same path tracer, same camera and
// random numbers as canopy; the BVH build and traversal are Embree's, and shading reads Embree's hit record alone
// (normal, distance, triangle id), as an Embree user's renderer does, never the scene's triangles.
#include "experiments/embree_accelerator.h"

#include "renderer/frames_of_width.h"
#include "renderer/wavefront.h"

#include <embree3/rtcore.h>

#include <tbb/parallel_for.h>

#include <atomic>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace canopy {
namespace {

RTCBuildQuality parse_quality(const std::string& quality) {
    if (quality == "low") return RTC_BUILD_QUALITY_LOW;
    if (quality == "medium") return RTC_BUILD_QUALITY_MEDIUM;
    if (quality == "high") return RTC_BUILD_QUALITY_HIGH;
    throw std::invalid_argument("unknown Embree quality '" + quality + "' (known: low, medium, high)");
}

void to_embree(const Ray& ray, RTCRayHit& rh) {
    rh.ray.org_x = ray.org.x, rh.ray.org_y = ray.org.y, rh.ray.org_z = ray.org.z;
    rh.ray.dir_x = ray.dir.x, rh.ray.dir_y = ray.dir.y, rh.ray.dir_z = ray.dir.z;
    rh.ray.tnear = ray.tmin;
    rh.ray.tfar = ray.tmax;
    rh.ray.time = 0.0f;
    rh.ray.mask = 0xffffffffu;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
}

// Two-level scenes: per instance, its first scene-wide triangle id and the matrix that takes its object-space normals
// (which Embree reports for instanced triangles) to world space.
struct EmbreeInstances {
    const uint32_t* prim_offsets = nullptr;
    const glm::mat3* normal_to_world = nullptr;
};

// Embree's hit record as the stream tracer keeps it: the distance, the world-space normal and the triangle id, all
// that shading reads.
struct EmbreeRecord {
    float t = std::numeric_limits<float>::infinity();
    uint32_t prim = Hit::kNone;
    Vec3 normal{0.0f};
    bool found() const { return prim != Hit::kNone; }
};

[[gnu::always_inline]] inline SurfaceHit shading_surface(const ShadingScene&, const Ray& ray, const EmbreeRecord& r) {
    return ray_surface(ray, r.t, r.normal, r.prim);
}

// A hit's triangle id numbered as in the flat scene, and its normal in world space.
[[gnu::always_inline]] inline EmbreeRecord record_of(const EmbreeInstances& instances, float t, uint32_t prim, uint32_t inst,
                                                     const Vec3& ng) {
    if (!instances.prim_offsets || inst == RTC_INVALID_GEOMETRY_ID) return {t, prim, ng};
    return {t, instances.prim_offsets[inst] + prim, instances.normal_to_world[inst] * ng};
}

EmbreeRecord record_of(const EmbreeInstances& instances, const RTCRayHit& rh) {
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return {};
    return record_of(instances, rh.ray.tfar, rh.hit.primID, rh.hit.instID[0], Vec3(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z));
}

// One ray at a time through rtcIntersect1; frames shade from Embree's hit record alone.
struct EmbreeTracer {
    RTCScene scene;
    EmbreeInstances instances;
    RTCRayHit intersect(const Ray& ray) const {
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        RTCRayHit rh;
        to_embree(ray, rh);
        rtcIntersect1(scene, &context, &rh);
        return rh;
    }
    bool closest(const Ray& ray, SurfaceHit& surface) const {
        const EmbreeRecord r = record_of(instances, intersect(ray));
        if (!r.found()) return false;
        surface = ray_surface(ray, r.t, r.normal, r.prim);
        return true;
    }
    // Shadow and ambient-occlusion rays through rtcOccluded1, which sets tfar to -inf on a hit.
    bool occluded(const Ray& ray) const {
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        RTCRayHit rh;
        to_embree(ray, rh);
        rtcOccluded1(scene, &context, &rh.ray);
        return rh.ray.tfar < 0.0f;
    }
    // Tests' and tools' query, with the barycentrics a Hit carries.
    bool closest(const Ray& ray, Hit& hit) const {
        const RTCRayHit rh = intersect(ray);
        const EmbreeRecord r = record_of(instances, rh);
        if (!r.found()) return false;
        hit = {r.t, rh.hit.u, rh.hit.v, r.prim};
        return true;
    }
};

// The stream tracer's batches through Embree's ray stream interface, rtcIntersect1M, told the rays are incoherent,
// or in packets of 16 consecutive rays through rtcIntersect16 (FrameSettings::embree_packets).
struct EmbreeBatchTracer {
    using Record = EmbreeRecord;
    struct Scratch {
        std::vector<RTCRayHit> rays;
        RTCRayHit16 packet;
        size_t bytes() const { return rays.capacity() * sizeof(RTCRayHit) + sizeof(RTCRayHit16); }
    };
    RTCScene scene;
    EmbreeInstances instances;
    bool packets = false;
    // Closest-hit batches of camera rays alone (--workload camera), in tile order: told coherent, as an Embree user's
    // primary rays are, where bounces are incoherent.
    bool coherent = false;
    RTCIntersectContextFlags closest_flags() const {
        return coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    }

    void closest(std::span<const Ray> rays, std::span<EmbreeRecord> hits, Scratch& scratch) const {
        if (packets) {
            for (size_t first = 0; first < rays.size(); first += 16)
                closest16(rays.subspan(first, std::min<size_t>(16, rays.size() - first)), hits.subspan(first), scratch.packet);
            return;
        }
        scratch.rays.resize(rays.size());
        for (size_t i = 0; i < rays.size(); ++i) to_embree(rays[i], scratch.rays[i]);
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        context.flags = closest_flags();
        rtcIntersect1M(scene, &context, scratch.rays.data(), unsigned(rays.size()), sizeof(RTCRayHit));
        for (size_t i = 0; i < rays.size(); ++i) hits[i] = record_of(instances, scratch.rays[i]);
    }

    // Shadow and ambient-occlusion batches through rtcOccluded1M or rtcOccluded16: a blocked ray's record is found.
    void occluded(std::span<const Ray> rays, std::span<EmbreeRecord> hits, Scratch& scratch) const {
        if (packets) {
            for (size_t first = 0; first < rays.size(); first += 16)
                occluded16(rays.subspan(first, std::min<size_t>(16, rays.size() - first)), hits.subspan(first), scratch.packet);
            return;
        }
        if (rays.empty()) return;
        scratch.rays.resize(rays.size());
        for (size_t i = 0; i < rays.size(); ++i) to_embree(rays[i], scratch.rays[i]);
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        context.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
        rtcOccluded1M(scene, &context, &scratch.rays[0].ray, unsigned(rays.size()), sizeof(RTCRayHit));
        for (size_t i = 0; i < rays.size(); ++i) hits[i] = blocked_record(scratch.rays[i].ray.tfar);
    }
    static EmbreeRecord blocked_record(float tfar) { return tfar < 0.0f ? EmbreeRecord{0.0f, 0, Vec3(0.0f)} : EmbreeRecord{}; }

    // Packet i's rays from rays[i], the rest of the 16 lanes invalid.
    static void fill16(std::span<const Ray> rays, RTCRay16& p, int* valid) {
        for (size_t i = 0; i < 16; ++i) {
            valid[i] = i < rays.size() ? -1 : 0;
            if (i >= rays.size()) continue;
            const Ray& r = rays[i];
            p.org_x[i] = r.org.x, p.org_y[i] = r.org.y, p.org_z[i] = r.org.z;
            p.dir_x[i] = r.dir.x, p.dir_y[i] = r.dir.y, p.dir_z[i] = r.dir.z;
            p.tnear[i] = r.tmin, p.tfar[i] = r.tmax, p.time[i] = 0.0f;
            p.mask[i] = 0xffffffffu, p.id[i] = uint32_t(i), p.flags[i] = 0;
        }
    }

    void occluded16(std::span<const Ray> rays, std::span<EmbreeRecord> hits, RTCRayHit16& p) const {
        alignas(64) int valid[16];
        fill16(rays, p.ray, valid);
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        context.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
        rtcOccluded16(valid, scene, &context, &p.ray);
        for (size_t i = 0; i < rays.size(); ++i) hits[i] = blocked_record(p.ray.tfar[i]);
    }

    void closest16(std::span<const Ray> rays, std::span<EmbreeRecord> hits, RTCRayHit16& p) const {
        alignas(64) int valid[16];
        fill16(rays, p.ray, valid);
        for (size_t i = 0; i < rays.size(); ++i) {
            p.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
            p.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
        }
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        context.flags = closest_flags();
        rtcIntersect16(valid, scene, &context, &p);
        for (size_t i = 0; i < rays.size(); ++i) {
            hits[i] = p.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID
                          ? EmbreeRecord{}
                          : record_of(instances, p.ray.tfar[i], p.hit.primID[i], p.hit.instID[0][i],
                                      Vec3(p.hit.Ng_x[i], p.hit.Ng_y[i], p.hit.Ng_z[i]));
        }
    }
};

class EmbreeAccelerator final : public Accelerator, public ForeignFrames {
public:
    // `objects` non-null: Embree's two-level BVH, a scene per object under a scene of instances.
    EmbreeAccelerator(const FlatScene& scene, const std::string& quality, int threads, const TwoLevelInput* objects)
        : flat_(scene), quality_name_(quality), quality_(parse_quality(quality)) {
        const std::string config = threads > 0 ? "threads=" + std::to_string(threads) : "";
        device_ = rtcNewDevice(config.c_str());
        if (!device_) throw std::runtime_error("Embree: cannot create a device");
        rtcSetDeviceMemoryMonitorFunction(device_, &EmbreeAccelerator::monitor, this);
        // Embree reads vertices with 16-byte loads: one float of padding after the last vertex.
        vertices_.resize(scene.triangles.size() * 9 + 1);
        std::memcpy(vertices_.data(), scene.triangles.data(), scene.triangles.size() * sizeof(Triangle));
        indices_.resize(scene.triangles.size() * 3);
        for (uint32_t i = 0; i < indices_.size(); ++i) indices_[i] = i;
        triangle_count_ = scene.triangles.size();
        if (objects) {
            objects_ = *objects;
            for (TwoLevelInstance& i : objects_->instances) {
                prim_offsets_.push_back(i.prim_offset);
                normal_to_world_.push_back(normal_matrix(i.to_world));
            }
            for (std::vector<Triangle>& tris : objects_->objects) tris.reserve(tris.size() + 1);  // Embree's padding
        }
    }

    ~EmbreeAccelerator() override {
        if (scene_) rtcReleaseScene(scene_);
        release_object_scenes();
        if (device_) rtcReleaseDevice(device_);
    }

    std::string library() const override { return "embree"; }
    std::string builder() const override { return ""; }
    std::string kernel() const override { return "embree"; }
    std::string quality() const override { return quality_name_ + (objects_ ? " two-level" : ""); }

    // A new scene with a new geometry over the shared buffers, so the commit is a full build.
    void prepare() override {
        if (scene_) rtcReleaseScene(scene_);
        if (objects_) return prepare_two_level();
        scene_ = rtcNewScene(device_);
        rtcSetSceneBuildQuality(scene_, quality_);
        RTCGeometry geometry = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
        rtcSetGeometryBuildQuality(geometry, quality_);
        rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices_.data(), 0,
                                   3 * sizeof(float), triangle_count_ * 3);
        rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices_.data(), 0,
                                   3 * sizeof(uint32_t), triangle_count_);
        rtcCommitGeometry(geometry);
        rtcAttachGeometry(scene_, geometry);
        rtcReleaseGeometry(geometry);
        build_bytes_ = 0;
    }

    void build() override {
        if (objects_) {
            tbb::parallel_for(size_t(0), object_scenes_.size(), [&](size_t i) {
                if (object_scenes_[i]) rtcCommitScene(object_scenes_[i]);
            });
        }
        rtcCommitScene(scene_);
        if (rtcGetDeviceError(device_) != RTC_ERROR_NONE) throw std::runtime_error("Embree: scene build failed");
    }

    // Two-level: the instance's new transform and a commit of the top scene, which rebuilds it over the
    // committed object scenes. Flat: the moved vertices, then a commit, which rebuilds the whole BVH.
    void move(const PlacementMove& move) override {
        RTCGeometry geometry = rtcGetGeometry(scene_, objects_ ? move.placement : 0);
        if (objects_) {
            rtcSetGeometryTransform(geometry, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, &move.to_world[0][0]);
            normal_to_world_[move.placement] = normal_matrix(move.to_world);
        } else {
            std::memcpy(vertices_.data() + size_t(move.first_triangle) * 9, flat_.triangles.data() + move.first_triangle,
                        size_t(move.triangle_count) * sizeof(Triangle));
            rtcUpdateGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0);
        }
        rtcCommitGeometry(geometry);
        rtcCommitScene(scene_);
        if (rtcGetDeviceError(device_) != RTC_ERROR_NONE) throw std::runtime_error("Embree: scene rebuild failed");
    }

    uint64_t render(const ShadingScene& scene, const PinholeCamera& camera, uint32_t frame, Image& image,
                    const std::function<void(float)>& on_tile) const override {
        if (scene.settings.tracer == TracerKind::Stream)
            return render_frame_stream(EmbreeBatchTracer{scene_, instances(), scene.settings.embree_packets,
                                                         scene.settings.workload == Workload::Camera},
                                       EmbreeTracer{scene_, instances()}, scene, camera, frame, image, on_tile);
        return render_frame(EmbreeTracer{scene_, instances()}, scene, camera, frame, image, on_tile);
    }

    // Recorded rays through rtcIntersect1 and rtcOccluded1, or the stream rows' calls (rtcIntersect1M and rtcOccluded1M,
    // or their 16-ray packet forms), chunk by chunk.
    void replay(const FrameSettings& settings, std::span<const RecordedRay> rays, std::span<Hit> hits) const override {
        const EmbreeTracer single{scene_, instances()};
        const EmbreeBatchTracer batches{scene_, instances(), settings.embree_packets};
        struct Scratch {
            EmbreeBatchTracer::Scratch calls;
            std::vector<EmbreeRecord> records;
        };
        replay_chunks<Scratch>(
            settings.tracer, rays, hits,
            [&](const Ray& ray, bool any, Hit& hit) {
                hit = Hit{};
                if (any) hit.prim = single.occluded(ray) ? 0 : Hit::kNone;
                else single.closest(ray, hit);
            },
            [&](bool any, std::span<const Ray> batch, std::span<Hit> answers, Scratch& scratch) {
                scratch.records.resize(batch.size());
                if (any) batches.occluded(batch, scratch.records, scratch.calls);
                else batches.closest(batch, scratch.records, scratch.calls);
                for (size_t k = 0; k < batch.size(); ++k) {
                    const EmbreeRecord& r = scratch.records[k];
                    answers[k] = r.found() ? Hit{r.t, 0, 0, r.prim} : Hit{};
                }
            });
    }

    Hit trace(const Ray& ray) const override {
        Hit hit;
        EmbreeTracer{scene_, instances()}.closest(ray, hit);
        return hit;
    }

    TraversalCounts count(const Ray&) const override {
        throw std::invalid_argument("Embree does not report what a ray visits: heatmaps need a canopy kernel");
    }

    void trace_batch(Query, std::span<const Ray>, std::span<Hit>) const override {
        throw std::invalid_argument("Embree's batches are traced by the stream tracer only: batch queries need a canopy kernel");
    }

    AcceleratorReport report(bool) const override {
        AcceleratorReport r;
        r.bytes = uint64_t(std::max<int64_t>(build_bytes_.load(), 0));  // net bytes the build allocated
        return r;
    }

private:
    EmbreeInstances instances() const {
        if (!objects_) return {};
        return {prim_offsets_.data(), normal_to_world_.data()};
    }

    // Normals transform by the inverse transpose of the instance's linear part.
    static glm::mat3 normal_matrix(const glm::mat4& to_world) { return glm::transpose(glm::inverse(glm::mat3(to_world))); }

    void release_object_scenes() {
        for (RTCScene s : object_scenes_)
            if (s) rtcReleaseScene(s);
        object_scenes_.clear();
    }

    // New object scenes and a new top scene of instances, so that build() commits everything from scratch.
    void prepare_two_level() {
        release_object_scenes();
        for (const std::vector<Triangle>& tris : objects_->objects) {
            if (tris.empty()) {
                object_scenes_.push_back(nullptr);
                continue;
            }
            RTCScene object = rtcNewScene(device_);
            rtcSetSceneBuildQuality(object, quality_);
            RTCGeometry geometry = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
            rtcSetGeometryBuildQuality(geometry, quality_);
            rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, tris.data(), 0,
                                       3 * sizeof(float), tris.size() * 3);
            rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices_.data(), 0,
                                       3 * sizeof(uint32_t), tris.size());
            rtcCommitGeometry(geometry);
            rtcAttachGeometry(object, geometry);
            rtcReleaseGeometry(geometry);
            object_scenes_.push_back(object);
        }
        scene_ = rtcNewScene(device_);
        rtcSetSceneBuildQuality(scene_, quality_);
        for (uint32_t i = 0; i < objects_->instances.size(); ++i) {
            const TwoLevelInstance& instance = objects_->instances[i];
            if (!object_scenes_[instance.object]) continue;
            RTCGeometry geometry = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_INSTANCE);
            rtcSetGeometryInstancedScene(geometry, object_scenes_[instance.object]);
            rtcSetGeometryTransform(geometry, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, &instance.to_world[0][0]);
            rtcCommitGeometry(geometry);
            rtcAttachGeometryByID(scene_, geometry, i);
            rtcReleaseGeometry(geometry);
        }
        build_bytes_ = 0;
    }

    static bool monitor(void* self, ssize_t bytes, bool) {
        static_cast<EmbreeAccelerator*>(self)->build_bytes_ += int64_t(bytes);
        return true;
    }

    const FlatScene& flat_;
    std::string quality_name_;
    RTCBuildQuality quality_;
    RTCDevice device_ = nullptr;
    RTCScene scene_ = nullptr;
    std::vector<float> vertices_;
    std::vector<uint32_t> indices_;
    size_t triangle_count_ = 0;
    std::atomic<int64_t> build_bytes_{0};
    std::optional<TwoLevelInput> objects_;
    std::vector<uint32_t> prim_offsets_;
    std::vector<glm::mat3> normal_to_world_;
    std::vector<RTCScene> object_scenes_;
};

}  // namespace

std::unique_ptr<Accelerator> make_embree_accelerator(const FlatScene& scene, const std::string& quality, int threads) {
    return std::make_unique<EmbreeAccelerator>(scene, quality, threads, nullptr);
}

std::unique_ptr<Accelerator> make_embree_two_level_accelerator(const Scene& scene, const FlatScene& flat,
                                                               const std::string& quality, int threads) {
    const TwoLevelInput objects = two_level_input(scene);
    return std::make_unique<EmbreeAccelerator>(flat, quality, threads, &objects);
}

}  // namespace canopy
