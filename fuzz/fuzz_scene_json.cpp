// The scene.json loader. Beside the input lie mesh.obj (with mesh.mtl) and mesh.gltf, one triangle each, so that
// inputs naming them reach mesh loading, instancing and baking.
#include "fuzz/fuzz_support.h"

namespace {

void write_meshes() {
    using canopy::fuzz::write_file;
    write_file("mesh.mtl", "newmtl red\nKd 0.8 0.1 0.1\nKe 0 0 0\n");
    write_file("mesh.obj", "mtllib mesh.mtl\no tri\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n");
    write_file("mesh.gltf",
               R"({"asset":{"version":"2.0"},"buffers":[{"byteLength":36,"uri":"data:application/octet-stream;base64,)"
               R"(AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}],"bufferViews":[{"buffer":0,"byteLength":36}],)"
               R"("accessors":[{"bufferView":0,"componentType":5126,"type":"VEC3","count":3}],)"
               R"("meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],"nodes":[{"mesh":0},{"mesh":0,)"
               R"("translation":[2,0,0]}],"scenes":[{"nodes":[0,1]}]})");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace canopy::fuzz;
    static const bool meshes_written = (write_meshes(), true);
    (void)meshes_written;
    load_and_flatten(write_file("scene.json", as_text(data, size)).string());
    return 0;
}
