// The signed crossing of a segment with a triangle by exact orientation predicates (any CGAL kernel), and the
// fixed directions of the rays that count exact winding numbers. Shared by the two CGAL translation units
// (exact_winding.cpp, self_intersections.cpp): include it only there (CGAL's flags, deform/CMakeLists.txt).
#pragma once
#include <CGAL/Kernel/global_functions.h>
#include <CGAL/enum.h>

#include <array>

namespace lidef {

// Fixed directions (deterministic), none along a coordinate axis or diagonal, where mesh edges often lie;
// each of length 1 within 2e-4.
inline constexpr std::array<std::array<double, 3>, 12> kRayDirections{{{0.8113, 0.4127, 0.4143},
                                                                       {-0.3171, 0.8893, 0.3297},
                                                                       {0.2203, -0.3307, 0.9177},
                                                                       {-0.6581, -0.5113, 0.5527},
                                                                       {0.5839, -0.7717, -0.2521},
                                                                       {-0.4379, 0.2293, -0.8693},
                                                                       {0.9291, -0.1733, 0.3267},
                                                                       {-0.1459, -0.9587, 0.2441},
                                                                       {0.3461, 0.6277, -0.6971},
                                                                       {-0.8867, 0.1039, -0.4507},
                                                                       {0.1277, 0.2909, 0.9481},
                                                                       {-0.5297, -0.6121, -0.5871}}};

// How the segment [p, q] meets the proper triangle (a, b, c): not at all; through its interior, leaving
// through its counter-clockwise side (+1 to the winding number at p) or entering it (-1); or degenerately (an
// end in the triangle's plane, or the line through an edge or a corner), where another direction is needed.
enum class Crossing { kNone, kLeaves, kEnters, kDegenerate };

template <class Point>
Crossing segment_crossing(const Point& a, const Point& b, const Point& c, const Point& p, const Point& q) {
  const CGAL::Orientation op = CGAL::orientation(a, b, c, p), oq = CGAL::orientation(a, b, c, q);
  if (op == oq && op != CGAL::ZERO) return Crossing::kNone;  // both ends on one side
  if (op == CGAL::ZERO || oq == CGAL::ZERO) return Crossing::kDegenerate;
  const CGAL::Orientation s[3] = {CGAL::orientation(p, q, a, b), CGAL::orientation(p, q, b, c),
                                  CGAL::orientation(p, q, c, a)};
  const bool has_pos = s[0] == CGAL::POSITIVE || s[1] == CGAL::POSITIVE || s[2] == CGAL::POSITIVE;
  const bool has_neg = s[0] == CGAL::NEGATIVE || s[1] == CGAL::NEGATIVE || s[2] == CGAL::NEGATIVE;
  if (has_pos && has_neg) return Crossing::kNone;  // the line passes beside the closed triangle
  if (s[0] == CGAL::ZERO || s[1] == CGAL::ZERO || s[2] == CGAL::ZERO) return Crossing::kDegenerate;
  // orientation(a, b, c, p) is the sign of det(b − a, c − a, p − a): negative when p lies behind the
  // counter-clockwise side, i.e. the segment leaves through the triangle's front.
  return op == CGAL::NEGATIVE ? Crossing::kLeaves : Crossing::kEnters;
}

}  // namespace lidef
