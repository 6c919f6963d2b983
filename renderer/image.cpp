#include "renderer/image.h"

#include <OpenImageIO/imageio.h>

#include <stdexcept>

namespace canopy {

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

void write_exr(const std::string& path, int width, int height, const std::vector<float>& rgb) {
    auto out = OIIO::ImageOutput::create(path);
    if (!out) throw std::runtime_error(path + ": cannot create image output: " + OIIO::geterror());
    OIIO::ImageSpec spec(width, height, 3, OIIO::TypeDesc::FLOAT);
    spec.attribute("compression", "zip");
    if (!out->open(path, spec) || !out->write_image(OIIO::TypeDesc::FLOAT, rgb.data()) || !out->close())
        throw std::runtime_error(path + ": cannot write EXR: " + out->geterror());
}

}  // namespace canopy
