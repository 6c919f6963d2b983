#include "renderer/image.h"
#include "base/output_path.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace canopy {

Image::Image(int width, int height, std::vector<float> sums) : width_(width), height_(height), rgb_(std::move(sums)) {
    if (rgb_.size() != size_t(width) * size_t(height) * 3)
        throw std::invalid_argument("an image of " + std::to_string(width) + "x" + std::to_string(height) + " from " +
                                    std::to_string(rgb_.size()) + " floats");
}

Image& Image::operator+=(const Image& other) {
    if (other.rgb_.size() != rgb_.size()) throw std::invalid_argument("adding images of different sizes");
    for (size_t i = 0; i < rgb_.size(); ++i) rgb_[i] += other.rgb_[i];
    return *this;
}

std::vector<float> Image::average(int samples) const {
    std::vector<float> out(rgb_.size());
    const float scale = samples > 0 ? 1.0f / float(samples) : 0.0f;
    for (size_t i = 0; i < rgb_.size(); ++i) out[i] = rgb_[i] * scale;
    return out;
}

double Image::mean(int samples) const {
    double sum = 0.0;
    for (float v : rgb_) sum += v;
    return rgb_.empty() || samples <= 0 ? 0.0 : sum / double(rgb_.size()) / double(samples);
}

namespace {

// IEC 61966-2-1's curve from linear light to the sRGB code value, both in [0, 1].
float srgb_encoded(float linear) {
    const float v = std::clamp(linear, 0.0f, 1.0f);
    return v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
}

}  // namespace

void write_image(const std::string& path, int width, int height, const std::vector<float>& rgb) {
    auto out = OIIO::ImageOutput::create(path);
    if (!out) throw std::runtime_error(path + ": cannot create image output: " + OIIO::geterror());
    const bool display = lower_extension(path) != ".exr";  // a PNG or JPEG: 8-bit sRGB
    OIIO::ImageSpec spec(width, height, 3, display ? OIIO::TypeDesc::UINT8 : OIIO::TypeDesc::FLOAT);
    std::vector<float> encoded;  // a display image's code values; an EXR is written from `rgb` as it is
    if (display) {
        encoded.resize(rgb.size());
        std::transform(rgb.begin(), rgb.end(), encoded.begin(), srgb_encoded);
        spec.attribute("oiio:ColorSpace", "sRGB");
    } else {
        spec.attribute("compression", "zip");
    }
    const float* pixels = display ? encoded.data() : rgb.data();
    if (!out->open(path, spec) || !out->write_image(OIIO::TypeDesc::FLOAT, pixels) || !out->close())
        throw std::runtime_error(path + ": cannot write the image: " + out->geterror());
}

std::vector<float> read_exr(const std::string& path, int width, int height) {
    auto in = OIIO::ImageInput::open(path);
    if (!in) throw std::runtime_error(path + ": cannot read image: " + OIIO::geterror());
    const OIIO::ImageSpec& spec = in->spec();
    if (spec.width != width || spec.height != height || spec.nchannels != 3)
        throw std::runtime_error(path + ": expected " + std::to_string(width) + "x" + std::to_string(height) +
                                 " RGB, found " + std::to_string(spec.width) + "x" + std::to_string(spec.height) + "x" +
                                 std::to_string(spec.nchannels));
    std::vector<float> rgb(size_t(width) * size_t(height) * 3);
    if (!in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, rgb.data())) throw std::runtime_error(path + ": " + in->geterror());
    return rgb;
}

double rms_error(const std::vector<float>& a, const std::vector<float>& b, int width, int height) {
    const OIIO::ImageSpec spec(width, height, 3, OIIO::TypeDesc::FLOAT);
    const OIIO::ImageBuf image_a(spec, const_cast<float*>(a.data())), image_b(spec, const_cast<float*>(b.data()));
    return OIIO::ImageBufAlgo::compare(image_a, image_b, 0.0f, 0.0f).rms_error;
}

}  // namespace canopy
