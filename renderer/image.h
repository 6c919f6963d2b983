#pragma once
#include "base/geometry.h"

#include <string>
#include <utility>
#include <vector>

namespace canopy {

// An RGB float image that accumulates samples; `average()` divides by the samples taken.
class Image {
public:
    Image(int width, int height) : width_(width), height_(height), rgb_(size_t(width) * size_t(height) * 3, 0.0f) {}
    // An image holding these sums (width x height x 3 floats), as another process accumulated them.
    Image(int width, int height, std::vector<float> sums);

    void add(int x, int y, const Vec3& c) {
        float* p = &rgb_[(size_t(y) * size_t(width_) + size_t(x)) * 3];
        p[0] += c.x, p[1] += c.y, p[2] += c.z;
    }
    void clear() { std::fill(rgb_.begin(), rgb_.end(), 0.0f); }
    // Adds another image's sums, pixel by pixel: the two must be the same size.
    Image& operator+=(const Image& other);
    // The accumulated sums, moved out (to send them to another process).
    std::vector<float> take_sums() && { return std::move(rgb_); }
    std::vector<float> average(int samples) const;
    // Mean over all pixels and channels of the average: the protocol's "mean pixel value".
    double mean(int samples) const;
    int width() const { return width_; }
    int height() const { return height_; }

private:
    int width_, height_;
    std::vector<float> rgb_;
};

// The extensions write_image takes (render -o checks them before rendering).
inline const std::vector<std::string> kImageExtensions = {".exr", ".png", ".jpg", ".jpeg"};

// Writes linear RGB through OpenImageIO, the format by the path's extension: an EXR as linear floats; a PNG or JPEG
// in 8 bits through the sRGB transfer curve, which viewers assume of them. Throws std::runtime_error naming the
// path on failure.
void write_image(const std::string& path, int width, int height, const std::vector<float>& rgb);

// Reads an RGB EXR written by write_image; throws std::runtime_error naming the path when it cannot be read or
// is not width x height x 3.
std::vector<float> read_exr(const std::string& path, int width, int height);

// Root-mean-square error over all pixels and channels, by OpenImageIO's image comparison.
double rms_error(const std::vector<float>& a, const std::vector<float>& b, int width, int height);

}  // namespace canopy
