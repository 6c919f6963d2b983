#pragma once
// Hit distances that keep their relative precision however short the hit. The watertight test (watertight.h) forms
// t from sheared, origin-relative vertex coordinates whose rounding errors scale with the triangle, not with t, so
// its relative error grows as the triangle's size over t. precise_t recomputes the distance of a hit the kernel
// found from the triangle's plane in double precision; the watertight test still decides hit or miss, so
// watertightness is unchanged (docs/results.md#precise-distances-for-short-hits).
#include "kernels/ray.h"

#include <glm/vec3.hpp>

#include <array>
#include <cmath>

namespace canopy {

namespace precise_distance_detail {

struct TwoTerms {
    double value, error;  // their sum is exact
};

// a + b = value + error exactly (Knuth's TwoSum; Shewchuk 1997, Theorem 7).
inline TwoTerms two_sum(double a, double b) {
    const double sum = a + b, b_virtual = sum - a;
    return {sum, (a - (sum - b_virtual)) + (b - b_virtual)};
}

// a * b = value + error exactly: the FMA rounds the product once, so it returns the product's rounding error.
inline TwoTerms two_product(double a, double b) {
    const double product = a * b;
    return {product, std::fma(a, b, -product)};
}

// An exact sum of doubles as a nonoverlapping expansion, smallest component first (Shewchuk 1997, "Adaptive
// Precision Floating-Point Arithmetic", Grow-Expansion with zero elimination): the largest component carries the
// exact sign, and their sum is the value within a double's rounding.
class Expansion {
public:
    void add(double b) {
        if (b == 0.0) return;  // a product of two float differences is mostly exact in double: its error part is 0
        int kept = 0;
        double carry = b;
        for (int i = 0; i < size_; ++i) {
            const TwoTerms s = two_sum(carry, parts_[i]);
            carry = s.value;
            if (s.error != 0.0) parts_[kept++] = s.error;
        }
        if (carry != 0.0) parts_[kept++] = carry;
        size_ = kept;
    }

    // sign * a * b * c, exactly: four doubles.
    void add_product(double a, double b, double c, double sign) {
        const TwoTerms ab = two_product(a, b);
        const TwoTerms high = two_product(ab.value, c), low = two_product(ab.error, c);
        for (const double part : {high.value, high.error, low.value, low.error}) add(sign * part);
    }

    double value() const {
        double sum = 0.0;
        for (int i = 0; i < size_; ++i) sum += parts_[i];
        return sum;
    }

private:
    std::array<double, 24> parts_;  // one per double added: six products of four
    int size_ = 0;
};

// (x × y) · z exactly, rounded to double: the six three-factor terms of the determinant summed as an expansion.
// Exact for any doubles without underflow; float-derived inputs have none (a product of three is >= 1e-135).
inline double exact_triple_product(const glm::dvec3& x, const glm::dvec3& y, const glm::dvec3& z) {
    Expansion sum;
    for (int i = 0; i < 3; ++i) {
        const int j = (i + 1) % 3, k = (i + 2) % 3;  // (x × y)_i = x_j y_k - x_k y_j
        sum.add_product(x[j], y[k], z[i], 1.0);
        sum.add_product(x[k], y[j], z[i], -1.0);
    }
    return sum.value();
}

// The error of n · z below, n = x × y computed in double, is at most (5 + O(u)) u sum_i (|x_j y_k| + |x_k y_j|) |z_i|
// with u = 2^-53 (two roundings in each cross component, three in the dot product; Higham 2002, "Accuracy and
// Stability of Numerical Algorithms", sec. 3.1): 8 u covers it and the bound's own rounding.
inline constexpr double kErrorBound = 8.0 * 0x1p-53;
// Accepted in double below this relative error, 64 times under a float's rounding (2^-24); exact above it.
inline constexpr double kMostRelativeError = 0x1p-30;

// (x × y) · z with a relative error below kMostRelativeError and its exact sign: in double where the error bound
// allows it, otherwise exactly: an origin nearer its plane than ~1e-6 of the triangle's size, or a ray within ~1e-6
// radians of that plane.
inline double triple_product(const glm::dvec3& x, const glm::dvec3& y, const glm::dvec3& n, const glm::dvec3& magnitude,
                             const glm::dvec3& z) {
    const double value = glm::dot(n, z);
    const double bound = kErrorBound * glm::dot(magnitude, glm::abs(z));
    return bound <= kMostRelativeError * std::abs(value) ? value : exact_triple_product(x, y, z);
}

}  // namespace precise_distance_detail

// The distance along `ray` to the plane of the triangle (v0, v1, v2), in double, for a hit the kernel found:
// t = n · (v0 - o) / n · d with n = (v1 - v0) × (v2 - v0) (the plane's equation solved for o + t d). The float
// differences are formed in double, exact unless a coordinate's two floats are more than 2^29 apart in magnitude;
// numerator and denominator each come within 2^-30 of exact with their exact signs (an origin exactly on the plane
// gives exactly 0), so t is within ~2^-29 relative of the exact distance at any length. NaN for a ray in the plane.
inline double precise_t(const Vec3& v0, const Vec3& v1, const Vec3& v2, const Ray& ray) {
    using namespace precise_distance_detail;
    const glm::dvec3 p0(v0), e1 = glm::dvec3(v1) - p0, e2 = glm::dvec3(v2) - p0;
    const glm::dvec3 n = glm::cross(e1, e2);
    // Per axis, the sum of the cross product's two terms' magnitudes: what its rounding error scales with.
    const glm::dvec3 magnitude = glm::abs(glm::dvec3(e1.y * e2.z, e1.z * e2.x, e1.x * e2.y)) +
                                 glm::abs(glm::dvec3(e1.z * e2.y, e1.x * e2.z, e1.y * e2.x));
    const double numerator = triple_product(e1, e2, n, magnitude, p0 - glm::dvec3(ray.org));
    const double denominator = triple_product(e1, e2, n, magnitude, glm::dvec3(ray.dir));
    return numerator / denominator;
}

inline double precise_t(const Triangle& triangle, const Ray& ray) {
    return precise_t(triangle.v0, triangle.v1, triangle.v2, ray);
}

// precise_t rounded to the nearest float: the distance a caller reports.
inline float precise_t_float(const Vec3& v0, const Vec3& v1, const Vec3& v2, const Ray& ray) {
    return float(precise_t(v0, v1, v2, ray));
}

// The t = 0 rule: a hit counts only beyond the ray's tmin by its precise distance, so an origin exactly on a
// surface never hits that surface (its precise t is exactly 0), whatever the kernel's float t came out as. NaN
// (a ray in the triangle's plane) does not count either.
inline bool precise_hit_counts(double precise_t, float tmin) { return precise_t > double(tmin); }

}  // namespace canopy
