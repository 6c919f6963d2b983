#pragma once
// An allocator for traversal data: large arrays are 2 MiB aligned and advised to use transparent huge
// pages, because incoherent rays touch nodes all over the tree and 4 KiB pages make every visit a
// likely TLB miss. Small arrays use the ordinary heap. The advice only takes where the heap hands out pages not
// yet touched: reused heap memory stays in 4 KiB pages (crytek-sponza's leaves did). A fresh mapping per array
// got every page huge but traced no faster and built slower, as the kernel zeroes each fresh page, so the heap
// stays (docs/results.md#builds-and-layouts).
#include <sys/mman.h>

#include <cstddef>
#include <cstdlib>
#include <new>
#include <type_traits>

namespace canopy {

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
        madvise(p, rounded, MADV_HUGEPAGE);  // advice only: without THP it is ignored
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
