// The OBJ loader and the .mtl it names. An input is the OBJ text, optionally followed by a line "--mtl--" and
// the text of fuzz.mtl, which seeds name with "mtllib fuzz.mtl".
#include "fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace canopy::fuzz;
    const std::string_view input = as_text(data, size);
    constexpr std::string_view separator = "\n--mtl--\n";
    const size_t split = input.find(separator);
    const std::string_view mtl = split == std::string_view::npos ? std::string_view() : input.substr(split + separator.size());
    write_file("fuzz.mtl", mtl);
    load_and_flatten(write_file("fuzz.obj", input.substr(0, split)).string());
    return 0;
}
