#pragma once
// A renderer's rays on disk, as NumPy reads them (`numpy.load`; canopy.load_rays and canopy.save_rays in Python): a
// .npy file (format version 1.0) holding one record a ray, a structured array of dtype
//
//     [('org', '<f4', (3,)), ('dir', '<f4', (3,)), ('tmin', '<f4'), ('tmax', '<f4'), ('any', 'u1'),
//      ('t', '<f4'), ('prim', '<u4'), ('u', '<f4'), ('v', '<f4')]
//
// packed (49 bytes a ray): the ray, whether it asks any hit (1) or the closest (0), and the hit it got when it was
// recorded (prim 4294967295 for none; t is then the ray's tmax; u and v are 0 for an any-hit query, whose t is the
// first hit found). Layout and fields: docs/workloads.md#recorded-rays.
#include "kernels/ray.h"

#include <string>
#include <vector>

namespace canopy {

struct RecordedRay {
    Ray ray;
    bool any = false;  // an any-hit query (a shadow ray, an occlusion probe), else closest hit
    Hit hit;           // what the ray hit when it was recorded
};

// Throws std::runtime_error naming the file when it cannot be written.
void write_rays(const std::string& path, const std::vector<RecordedRay>& rays);
// Throws std::runtime_error naming the file and the part of it that is not such an array.
std::vector<RecordedRay> read_rays(const std::string& path);

}  // namespace canopy
