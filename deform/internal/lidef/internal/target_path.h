// Rotation-aware paths of handle targets (docs/solver.md, "Continuation"). A 180° twist moves each handle of
// the twisted end to the opposite side of the axis; interpolating positions linearly sends every handle
// through the axis, i.e. through a collapsed map. A person dragging turns the end instead. A TargetPath does
// the same: per group of handles, the best rigid motion between consecutive keyframes is interpolated by
// angle (about a fixed axis) and translation, and only what the rigid motion does not explain is interpolated
// linearly. Both ends of every segment are met exactly, so the grouping shapes only the way, never the
// destination.
#pragma once
#include <vector>

#include "lidef/types.h"

namespace lidef {

// Groups handles whose sources lie within `link_distance` of each other (single linkage: chains count), so
// the handles of one dragged part move as one rigid body. Returns #h group ids 0, 1, ... in order of first
// handle. sources: #h by 3.
std::vector<int> group_handles(const MatX3d& sources, double link_distance);

class TargetPath {
 public:
  // keyframes: K+1 arrays of #h by 3 positions (K ≥ 1 segments): keyframes[0] where the handles are now,
  // keyframes[K] the final targets, those between are waypoints visited in order. groups: #h ids
  // (group_handles, or the scenario's "group" keys). A group of fewer than 3 handles, or of handles on one
  // line, has no defined rotation and moves by translation plus linear residual.
  TargetPath(const std::vector<MatX3d>& keyframes, const std::vector<int>& groups);

  int segments() const { return static_cast<int>(segments_.size()); }
  // Positions at s ∈ [0, segments()]: segment k = floor(s) (the last one for s = segments()). #h by 3.
  MatX3d at(double s) const;
  // The largest rotation angle of any group in segment k, in radians (0..π).
  double max_angle(int k) const;
  // The largest distance any handle travels along the straight line of segment k.
  double max_displacement(int k) const;

 private:
  struct GroupMotion {
    std::vector<int> handles;
    Vec3 axis = Vec3::UnitZ();
    double angle = 0;  // rotation about `axis` through the start centroid, radians
    Vec3 from_centroid = Vec3::Zero(), to_centroid = Vec3::Zero();
    MatX3d residual;  // per handle of the group: end − (rigid motion of the start)
  };
  struct Segment {
    MatX3d start, end;  // #h by 3
    std::vector<GroupMotion> groups;
  };
  std::vector<Segment> segments_;
};

}  // namespace lidef
