// The winding number of a closed triangle surface about a point, decided with exact predicates (CGAL): an
// integer, never a rounded solid-angle sum.
#pragma once
#include <optional>
#include <vector>

#include "lidef/types.h"

namespace lidef {

// Winding number about p of the triangles `faces` of (V #V by 3, F #F by 3), which must form a closed
// oriented surface (every edge used once in each direction); counter-clockwise seen from outside counts +1
// inside. Counted as the signed crossings of a segment from p to a point beyond the surface's bounding
// box, with exact orientation predicates on the given doubles; a segment through an edge, a vertex or a
// triangle's plane at p is replaced by another direction. nullopt when p lies in the plane of a triangle
// it might cross for every direction tried (p on the surface, or an unlucky point) — the caller treats
// that as not decided. Triangles with collinear corners bound no area and are skipped.
std::optional<int> exact_winding_number(const MatX3d& V, const MatX3i& F, const std::vector<int>& faces,
                                        const Vec3& p);

}  // namespace lidef
