#pragma once
// Tree quality metrics beyond the binary tree's SAH (bvh.h): SAH of wide trees, end-point overlap (eq. 3 of Aila,
// Karras and Laine 2013, "On Quality Metrics of Bounding Volume Hierarchies") of any tree, and how much siblings
// overlap.
#include "accel/bvh.h"
#include "accel/wide_bvh.h"

#include <span>

namespace canopy {

// Area of the part of triangle t inside box b (the triangle clipped to the box's six planes).
double clipped_area(const Triangle& t, const BBox& b);

// Eq. 1 over a wide tree: every wide node costs C_inn once (one box test of all its children), every leaf
// C_tri per triangle, each weighted by its box's area relative to the root's.
template <int N>
double sah_cost(const WideBvh<N>& bvh, SahCosts costs = {});

// Eq. 3: sum over nodes n of C_n * A((S \ Q(n)) intersected with n) / A(S), where Q(n) are the triangles
// referenced in n's subtree and C_n is C_inn for inner nodes and C_tri T_n for leaves. Exact: every triangle
// is clipped to every node box it overlaps. A triangle referenced by several leaves (split references)
// belongs to every subtree that holds one of its references.
double epo_cost(const Bvh& bvh, std::span<const Triangle> triangles, SahCosts costs = {});
template <int N>
double epo_cost(const WideBvh<N>& bvh, std::span<const Triangle> triangles, SahCosts costs = {});

// How much sibling boxes overlap: the sum over inner nodes of the half area of their two children's boxes'
// intersection, over the sum of the inner nodes' half areas: 0 where a gap separates every node's children, up to 1
// where every child is its parent's box (children that touch share a face, whose area counts: a ray across it
// enters both). Of an object-split tree, it says what object splits could not separate,
// which is what spatial splits (Stich et al. 2009, sec. 3: they are tried where object splits' children overlap)
// can recover.
double sibling_overlap(const Bvh& bvh);

}  // namespace canopy
