// Exact detection of intersecting triangle pairs in a triangle mesh (CGAL exact predicates).
#pragma once
#include <utility>
#include <vector>

#include "lidef/types.h"

namespace lidef {

// Returns every pair (i, j), i < j, 0-based and sorted, of faces of (V #V by 3, F #F by 3) that share a point
// they are not supposed to share:
//   - no common vertex index: the closed triangles intersect at all (touching counts);
//   - one common vertex: they have a point other than that vertex in common;
//   - a common edge: they are coplanar and lie on the same side of the edge (folded over, overlapping);
//   - all three vertices common (duplicate faces): always reported.
// Faces whose three corners are collinear (degenerate) or that repeat a vertex index are skipped; the
// validator reports them separately. Faces must index valid vertices with finite coordinates.
// Predicates are exact, so the answer does not depend on round-off. Cost: a sort-and-sweep over the face
// bounding boxes, then exact tests on overlapping pairs only.
std::vector<std::pair<int, int>> find_self_intersections(const MatX3d& V, const MatX3i& F);

}  // namespace lidef
