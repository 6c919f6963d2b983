#pragma once
// The one parallel executor that all builders share: fork-join over subtrees and parallel
// reductions over ranges, on TBB. Work below `grain` runs serially so that small subtrees do not
// pay for tasks. The number of threads is set once by the caller (tbb::global_control).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>

#include <cstddef>

namespace canopy::parallel {

// Runs a and b, concurrently when the work they stand for is at least `grain` items.
template <class A, class B>
void fork_join(size_t work, size_t grain, A&& a, B&& b) {
    if (work >= grain) {
        tbb::parallel_invoke(a, b);
    } else {
        a();
        b();
    }
}

// Reduces f(begin, end) -> T over [0, n) in chunks of at least `grain`, combining with `join`.
// Deterministic in value for an associative, commutative join (box unions, bin counts).
template <class T, class F, class Join>
T reduce(size_t n, size_t grain, const T& identity, F&& f, Join&& join) {
    if (n < 2 * grain) return n ? f(size_t{0}, n) : identity;
    return tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, n, grain), identity,
        [&](const tbb::blocked_range<size_t>& r, T acc) { return join(acc, f(r.begin(), r.end())); },
        join);
}

template <class F>
void for_each(size_t n, size_t grain, F&& f) {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, grain), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) f(i);
    });
}

}  // namespace canopy::parallel
