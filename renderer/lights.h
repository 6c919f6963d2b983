#pragma once
// The lights next-event estimation samples (`--workload nee`): the emitting triangles of a --materials scene, or, in
// a scene lit by the protocol's white sky alone, a sun beside the sky (docs/workloads.md#nee). Both are sampled by
// solid angle pdfs that multiple importance sampling weighs against the cosine-weighted bounce (Veach 1997, ch. 9).
#include "renderer/sampling.h"
#include "scenes/scene.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

namespace canopy {

// A sampled light direction from a shading point: where it goes, how far (infinity for the sun), what it carries and
// its solid angle pdf.
struct LightSample {
    Vec3 direction;
    float distance;
    Vec3 radiance;
    float pdf;
};

// The power heuristic with beta = 2 (Veach 1997, eq. 9.15), for one sample of each strategy.
inline float power_heuristic(float pdf, float other) {
    const float a = pdf * pdf, b = other * other;
    return a + b > 0.0f ? a / (a + b) : 0.0f;
}

inline float luminance(const Vec3& c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

class Lights {
public:
    // The sun: towards +y (every shared scene's up), tilted so that walls facing +x and +z catch it too; its disc
    // 0.5 degrees in radius, with the irradiance the white sky gives a surface facing up (pi) at normal incidence.
    static constexpr float kSunRadius = 0.5f * std::numbers::pi_v<float> / 180.0f;
    static Vec3 sun_direction() { return glm::normalize(Vec3(0.3f, 1.0f, 0.2f)); }
    static float sun_solid_angle() { return 2.0f * std::numbers::pi_v<float> * (1.0f - std::cos(kSunRadius)); }
    static float sun_radiance() { return std::numbers::pi_v<float> / sun_solid_angle(); }

    // The scene's emitters when `emitters` (a --materials scene with emission), else the sun.
    Lights(const FlatScene& flat, bool emitters) : flat_(flat) {
        if (!emitters) return;
        for (uint32_t prim = 0; prim < flat.triangles.size(); ++prim) {
            const Vec3 le = flat.materials[flat.material[prim]].emission;
            const Triangle& t = flat.triangles[prim];
            const float power = 0.5f * glm::length(glm::cross(t.v1 - t.v0, t.v2 - t.v0)) * luminance(le);
            if (!(power > 0.0f) || !std::isfinite(power)) continue;
            emitters_.push_back(prim);
            cdf_.push_back(total_ + power);
            total_ = cdf_.back();
        }
        if (emitters_.empty()) total_ = 0.0f;
    }

    bool has_sun() const { return emitters_.empty(); }

    // A light sample seen from `p`: an emitter chosen by power, a point uniform on it; or a direction uniform in the
    // sun's cone.
    LightSample sample(const Vec3& p, float u0, float u1, float u2) const {
        if (has_sun()) return sample_sun(u0, u1);
        const size_t k = std::min<size_t>(std::upper_bound(cdf_.begin(), cdf_.end(), u0 * total_) - cdf_.begin(), emitters_.size() - 1);
        const uint32_t prim = emitters_[k];
        const Triangle& t = flat_.triangles[prim];
        const float su = std::sqrt(u1);  // uniform on the triangle (pbrt-v4 sec. 6.5.1)
        const Vec3 q = t.v0 * (1.0f - su) + t.v1 * (su * (1.0f - u2)) + t.v2 * (su * u2);
        const Vec3 to = q - p;
        const float d2 = glm::dot(to, to), d = std::sqrt(d2);
        const Vec3 wi = to / d;
        const Vec3 n = geometric_normal(t);
        const float n_len = glm::length(n), cos_light = std::abs(glm::dot(n, wi)) / n_len;
        if (!(d > 0.0f) || !(cos_light > 0.0f)) return {wi, d, Vec3(0.0f), 0.0f};
        const Vec3 le = flat_.materials[flat_.material[prim]].emission;
        return {wi, d, le, emitter_area_pdf(le) * d2 / cos_light};
    }

    // The solid angle pdf with which sample() picks the direction `wi` from `p` to a point at distance `d` on emitter
    // `prim` whose unit normal makes `cos_light` with it: the pick by power over the area cancels the area.
    float emitter_pdf(const Vec3& le, float d, float cos_light) const {
        return cos_light > 0.0f ? emitter_area_pdf(le) * d * d / cos_light : 0.0f;
    }
    // The sun's radiance seen along `dir` (zero outside its disc) and the pdf with which sample() draws `dir`.
    bool in_sun(const Vec3& dir) const { return has_sun() && glm::dot(dir, sun_direction()) >= std::cos(kSunRadius); }
    float sun_pdf() const { return 1.0f / sun_solid_angle(); }

private:
    float emitter_area_pdf(const Vec3& le) const { return total_ > 0.0f ? luminance(le) / total_ : 0.0f; }

    LightSample sample_sun(float u0, float u1) const {
        // Uniform in the cone about the sun's direction (pbrt-v4 sec. A.5.4), in the basis of cosine_direction.
        const float cos_max = std::cos(kSunRadius), cos_t = 1.0f - u0 * (1.0f - cos_max);
        const float sin_t = std::sqrt(std::max(0.0f, 1.0f - cos_t * cos_t));
        const Vec3 n = sun_direction();
        const float sign = std::copysign(1.0f, n.z), a = -1.0f / (sign + n.z), b = n.x * n.y * a;
        const Vec3 t(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x), s(b, sign + n.y * n.y * a, -n.y);
        const auto [cos_phi, sin_phi] = turn_cos_sin(u1);
        const Vec3 wi = sin_t * cos_phi * t + sin_t * sin_phi * s + cos_t * n;
        return {wi, std::numeric_limits<float>::infinity(), Vec3(sun_radiance()), sun_pdf()};
    }

    const FlatScene& flat_;
    std::vector<uint32_t> emitters_;
    std::vector<float> cdf_;
    float total_ = 0.0f;
};

}  // namespace canopy
