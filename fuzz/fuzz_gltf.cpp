// The glTF loader: an input that starts with the binary container's magic "glTF" is loaded as fuzz.glb, any
// other as fuzz.gltf. buffer.bin lies beside it (48 bytes: four float positions), for inputs naming it as a uri.
#include "fuzz/fuzz_support.h"

#include <array>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace canopy::fuzz;
    static const bool buffer_written = [] {
        const std::array<float, 12> positions{0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
        write_file("buffer.bin", {reinterpret_cast<const char*>(positions.data()), sizeof positions});
        return true;
    }();
    (void)buffer_written;
    const std::string_view input = as_text(data, size);
    load_and_flatten(write_file(input.starts_with("glTF") ? "fuzz.glb" : "fuzz.gltf", input).string());
    return 0;
}
