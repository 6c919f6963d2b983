#pragma once
// The tools' Embree scene: a flat scene's triangles as one Embree 3 geometry over shared buffers, built at MEDIUM
// quality (binned SAH) as canopy's `embree medium` row builds it, with Embree's API alone.
#include "scenes/scene.h"

#include <embree3/rtcore.h>

#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

namespace canopy::tools {

class EmbreeScene {
public:
    EmbreeScene(const canopy::FlatScene& flat, int threads) {
        const std::string config = threads > 0 ? "threads=" + std::to_string(threads) : "";
        device_ = rtcNewDevice(config.c_str());
        if (!device_) throw std::runtime_error("Embree: cannot create a device");
        vertices_.resize(flat.triangles.size() * 9 + 1);  // Embree reads vertices with 16-byte loads: one float of padding
        std::memcpy(vertices_.data(), flat.triangles.data(), flat.triangles.size() * sizeof(canopy::Triangle));
        indices_.resize(flat.triangles.size() * 3);
        for (uint32_t i = 0; i < indices_.size(); ++i) indices_[i] = i;
        scene_ = rtcNewScene(device_);
        rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_MEDIUM);
        RTCGeometry geometry = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
        rtcSetGeometryBuildQuality(geometry, RTC_BUILD_QUALITY_MEDIUM);
        rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices_.data(), 0,
                                   3 * sizeof(float), flat.triangles.size() * 3);
        rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices_.data(), 0,
                                   3 * sizeof(uint32_t), flat.triangles.size());
        rtcCommitGeometry(geometry);
        rtcAttachGeometry(scene_, geometry);
        rtcReleaseGeometry(geometry);
        rtcCommitScene(scene_);
        if (rtcGetDeviceError(device_) != RTC_ERROR_NONE) throw std::runtime_error("Embree: scene build failed");
    }
    ~EmbreeScene() {
        rtcReleaseScene(scene_);
        rtcReleaseDevice(device_);
    }
    EmbreeScene(const EmbreeScene&) = delete;
    EmbreeScene& operator=(const EmbreeScene&) = delete;

    RTCScene scene() const { return scene_; }

private:
    RTCDevice device_ = nullptr;
    RTCScene scene_ = nullptr;
    std::vector<float> vertices_;
    std::vector<uint32_t> indices_;
};

}  // namespace canopy::tools
