#pragma once
// The one parallel executor that all builders share: fork-join over subtrees and parallel
// reductions over ranges, on TBB. Work below `grain` runs serially so that small subtrees do not
// pay for tasks. The number of threads is set once by the caller (tbb::global_control).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cstddef>
#include <vector>

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

// reduce, with the identity made by make_identity() only when the range is split: serial work (most calls, in a
// builder's lower levels) then never builds it, which matters when it is large (a grid of bins).
template <class MakeIdentity, class F, class Join>
auto reduce_lazy(size_t n, size_t grain, MakeIdentity&& make_identity, F&& f, Join&& join) {
    if (n == 0) return make_identity();
    if (n < 2 * grain) return f(size_t{0}, n);
    return reduce(n, grain, make_identity(), f, join);
}

// Sums f(i) over [0, n) in fixed blocks of `grain`, the blocks added in order: the same double with any number
// of threads (a floating-point reduce is not associative, so its value would depend on how the range was cut).
template <class F>
double sum_in_order(size_t n, size_t grain, F&& f);

template <class F>
void for_each(size_t n, size_t grain, F&& f) {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, grain), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) f(i);
    });
}

template <class F>
double sum_in_order(size_t n, size_t grain, F&& f) {
    const size_t blocks = (n + grain - 1) / grain;
    std::vector<double> partial(blocks, 0.0);
    for_each(blocks, 1, [&](size_t b) {
        for (size_t i = b * grain; i < std::min(n, (b + 1) * grain); ++i) partial[b] += f(i);
    });
    double total = 0.0;
    for (double p : partial) total += p;
    return total;
}

}  // namespace canopy::parallel
