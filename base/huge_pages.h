#pragma once
// Large arrays on 2 MiB transparent huge pages. Traversal data, because incoherent rays touch nodes all over the
// tree and 4 KiB pages make every visit a likely TLB miss; the scene's triangles, the references and the build's
// arrays, because in a virtual machine a first touch of each 4 KiB page costs more than writing it, and a huge page
// takes one fault where 4 KiB pages take 512 (docs/results.md#huge-pages-for-large-arrays). The advice only takes
// where the heap hands out pages not yet touched: reused heap memory stays in 4 KiB pages. A fresh mapping per
// array got every page huge but traced no faster and built slower, as the kernel zeroes each fresh page, so the
// heap stays (docs/results.md#builds-and-layouts).
#include <sys/mman.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <iterator>
#include <new>
#include <type_traits>

namespace canopy {

// Advises huge pages over the whole 2 MiB pages inside [data, data + bytes). Only advice: where the kernel has
// transparent huge pages off, or none is free, the memory is the same in 4 KiB pages.
inline void advise_huge_pages(const void* data, size_t bytes) {
    constexpr uintptr_t kHugePage = uintptr_t(2) << 20;
    const auto start = reinterpret_cast<uintptr_t>(data);
    const uintptr_t begin = (start + kHugePage - 1) & ~(kHugePage - 1);
    const uintptr_t end = (start + bytes) & ~(kHugePage - 1);
    if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
}

// v.resize(n), the storage it grows into advised before anything touches it: for arrays whose type is shared with
// code that takes a plain std::vector (the flat scene, the references).
template <class Vector>
void resize_on_huge_pages(Vector& v, size_t n) {
    if (v.capacity() < n) {
        Vector grown(v.get_allocator());
        grown.reserve(n);
        advise_huge_pages(grown.data(), n * sizeof(typename Vector::value_type));
        grown.assign(std::make_move_iterator(v.begin()), std::make_move_iterator(v.end()));
        v.swap(grown);
    }
    v.resize(n);
}

// For arrays of canopy's own: 2 MiB aligned, so that every page of a large one can be huge. Small arrays use
// the ordinary heap.
template <class T>
struct HugePageAllocator {
    using value_type = T;
    static constexpr size_t kHugePage = size_t(2) << 20;

    HugePageAllocator() = default;
    template <class U>
    HugePageAllocator(const HugePageAllocator<U>&) {}

    T* allocate(size_t n) {
        const size_t bytes = n * sizeof(T);
        if (bytes < kHugePage) {
            if (void* p = std::aligned_alloc(64, (bytes + 63) / 64 * 64)) return static_cast<T*>(p);
            throw std::bad_alloc();
        }
        const size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
        void* p = std::aligned_alloc(kHugePage, rounded);
        if (!p) throw std::bad_alloc();
        advise_huge_pages(p, rounded);
        return static_cast<T*>(p);
    }
    void deallocate(T* p, size_t) { std::free(p); }

    // Default-initialises, so resize() leaves the plain node and leaf types unwritten: the parallel code that
    // fills them touches their pages first, instead of one thread zeroing them all beforehand.
    template <class U>
    void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
        ::new (static_cast<void*>(p)) U;
    }

    template <class U>
    bool operator==(const HugePageAllocator<U>&) const { return true; }
};

}  // namespace canopy
