#include "renderer/ray_file.h"

#include <cmath>
#include <cstring>
#include <fstream>
#include <stdexcept>

namespace canopy {
namespace {

constexpr char kMagic[] = "\x93NUMPY";
constexpr size_t kRecordBytes = 49;
constexpr const char* kDescr =
    "[('org', '<f4', (3,)), ('dir', '<f4', (3,)), ('tmin', '<f4'), ('tmax', '<f4'), ('any', '|u1'), "
    "('t', '<f4'), ('prim', '<u4'), ('u', '<f4'), ('v', '<f4')]";

// The header dictionary, padded with spaces and a newline so that the data starts at a multiple of 64 bytes.
std::string header(size_t count) {
    std::string dict = std::string("{'descr': ") + kDescr + ", 'fortran_order': False, 'shape': (" + std::to_string(count) + ",), }";
    const size_t unpadded = 10 + dict.size() + 1;
    dict.append((64 - unpadded % 64) % 64, ' ');
    return dict + "\n";
}

template <class T>
void put(unsigned char*& out, const T& value) {
    std::memcpy(out, &value, sizeof value);
    out += sizeof value;
}
template <class T>
T take(const unsigned char*& in) {
    T value;
    std::memcpy(&value, in, sizeof value);
    in += sizeof value;
    return value;
}

// `text` without its spaces: the descr as NumPy writes it may space its tuples differently.
std::string unspaced(const std::string& text) {
    std::string out;
    for (char c : text)
        if (c != ' ') out += c;
    return out;
}

}  // namespace

void write_rays(const std::string& path, const std::vector<RecordedRay>& rays) {
    std::ofstream out(path, std::ios::binary);
    const std::string dict = header(rays.size());
    const uint16_t length = uint16_t(dict.size());
    out.write(kMagic, 6);
    out.put(1), out.put(0);
    out.write(reinterpret_cast<const char*>(&length), 2);
    out.write(dict.data(), std::streamsize(dict.size()));
    std::vector<unsigned char> block;
    for (size_t first = 0; first < rays.size(); first += 65536) {
        const size_t count = std::min<size_t>(65536, rays.size() - first);
        block.resize(count * kRecordBytes);
        unsigned char* p = block.data();
        for (size_t i = first; i < first + count; ++i) {
            const RecordedRay& r = rays[i];
            for (int a = 0; a < 3; ++a) put(p, r.ray.org[a]);
            for (int a = 0; a < 3; ++a) put(p, r.ray.dir[a]);
            put(p, r.ray.tmin), put(p, r.ray.tmax), put(p, uint8_t(r.any));
            put(p, r.hit.t), put(p, r.hit.prim), put(p, r.hit.u), put(p, r.hit.v);
        }
        out.write(reinterpret_cast<const char*>(block.data()), std::streamsize(block.size()));
    }
    if (!out) throw std::runtime_error(path + ": cannot write the rays");
}

std::vector<RecordedRay> read_rays(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error(path + ": cannot open the rays");
    const auto refuse = [&](const std::string& what) { return std::runtime_error(path + ": not a ray file of canopy's: " + what); };
    char magic[6];
    unsigned char version[2];
    if (!in.read(magic, 6) || std::memcmp(magic, kMagic, 6) != 0) throw refuse("no .npy magic string");
    if (!in.read(reinterpret_cast<char*>(version), 2) || (version[0] != 1 && version[0] != 2))
        throw refuse("format version " + std::to_string(int(version[0])) + " (1 and 2 are read)");
    uint32_t length = 0;
    if (version[0] == 1) {
        uint16_t short_length = 0;
        in.read(reinterpret_cast<char*>(&short_length), 2);
        length = short_length;
    } else {
        in.read(reinterpret_cast<char*>(&length), 4);
    }
    std::string dict(length, '\0');
    if (!in || length > (1u << 20) || !in.read(dict.data(), length)) throw refuse("header cut short");
    const std::string flat = unspaced(dict);
    if (flat.find(unspaced(std::string("'descr': ") + kDescr)) == std::string::npos)
        throw refuse("its 'descr' is not canopy's ray record (docs/workloads.md#recorded-rays)");
    if (flat.find("'fortran_order':False") == std::string::npos) throw refuse("'fortran_order' is not False");
    const size_t shape = flat.find("'shape':(");
    if (shape == std::string::npos) throw refuse("no 'shape'");
    char* end = nullptr;
    const unsigned long long count = std::strtoull(flat.c_str() + shape + 9, &end, 10);
    if (end == flat.c_str() + shape + 9 || (*end != ',' && *end != ')') || (*end == ',' && end[1] != ')'))
        throw refuse("'shape' is not one dimension");
    in.seekg(0, std::ios::end);
    const uint64_t data_bytes = uint64_t(in.tellg()) - (version[0] == 1 ? 10u : 12u) - length;
    if (data_bytes != count * kRecordBytes)
        throw refuse("'shape' says " + std::to_string(count) + " rays, the file holds " + std::to_string(data_bytes) + " bytes of them");
    in.seekg(std::streamoff((version[0] == 1 ? 10u : 12u) + length));
    std::vector<RecordedRay> rays(count);
    std::vector<unsigned char> block;
    for (size_t first = 0; first < count; first += 65536) {
        const size_t n = std::min<size_t>(65536, count - first);
        block.resize(n * kRecordBytes);
        if (!in.read(reinterpret_cast<char*>(block.data()), std::streamsize(block.size()))) throw refuse("cut short");
        const unsigned char* p = block.data();
        for (size_t i = first; i < first + n; ++i) {
            RecordedRay& r = rays[i];
            for (int a = 0; a < 3; ++a) r.ray.org[a] = take<float>(p);
            for (int a = 0; a < 3; ++a) r.ray.dir[a] = take<float>(p);
            r.ray.tmin = take<float>(p), r.ray.tmax = take<float>(p);
            const uint8_t any = take<uint8_t>(p);
            if (any > 1) throw refuse("ray " + std::to_string(i) + "'s 'any' is " + std::to_string(any) + ", not 0 or 1");
            r.any = any;
            r.hit.t = take<float>(p), r.hit.prim = take<uint32_t>(p), r.hit.u = take<float>(p), r.hit.v = take<float>(p);
            const auto finite = [](const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); };
            if (!finite(r.ray.org) || !finite(r.ray.dir) || r.ray.dir == Vec3(0.0f))
                throw refuse("ray " + std::to_string(i) + "'s 'org' or 'dir' is not finite, or 'dir' is zero");
            if (!(r.ray.tmin >= 0.0f) || !(r.ray.tmax >= r.ray.tmin))
                throw refuse("ray " + std::to_string(i) + "'s interval ['tmin', 'tmax'] is not 0 <= tmin <= tmax");
        }
    }
    return rays;
}

}  // namespace canopy
