// The maps the σ3 explorer studies (docs/explorer.md): a harmonic map on a closed ball, given as a harmonic
// polynomial (harmonic_polynomials.h) or as a cage map, behind one interface with f, J, H and T at a point.
#pragma once
#include <string>

#include "lidef/cage.h"
#include "lidef/explorer/harmonic_polynomials.h"
#include "lidef/green_coordinates.h"
#include "lidef/singular_value_derivatives.h"
#include "lidef/types.h"

namespace lidef {

// The closed ball the map is studied on.
struct Ball {
  Vec3 center = Vec3::Zero();
  double radius = 1;
  bool contains(const Vec3& p) const { return (p - center).norm() <= radius; }
};

// A map with f (3), J (3 by 3), H (3 of 3 by 3) and third derivatives T (3 by 3 of 3 by 3) at a point
// (PolyJet layout).
class ExplorerMap {
 public:
  virtual ~ExplorerMap() = default;
  virtual PolyJet jet(const Vec3& p) const = 0;
  virtual Vec3 value(const Vec3& p) const { return jet(p).f; }
  // J alone (cheaper for cage maps).
  virtual Mat3 jacobian(const Vec3& p) const { return jet(p).J; }
  // True when T is exact (polynomials); false when it comes from finite differences (cage maps).
  virtual bool exact_third_derivatives() const = 0;
  virtual std::string description() const = 0;
};

class PolynomialExplorerMap : public ExplorerMap {
 public:
  explicit PolynomialExplorerMap(HarmonicPolynomialMap map) : map_(std::move(map)) {}
  PolyJet jet(const Vec3& p) const override { return map_.jet(p, 3); }
  Vec3 value(const Vec3& p) const override { return map_.value(p); }
  bool exact_third_derivatives() const override { return true; }
  std::string description() const override;
  const HarmonicPolynomialMap& map() const { return map_; }

 private:
  HarmonicPolynomialMap map_;
};

// A cage map f = Σ y_i basis_i (green_coordinates.h). f, J, H are the closed forms; T is the central
// difference of the closed-form H with step `fd_step` (relative error ~1e-7 at the distances the ball keeps
// from the cage).
class CageExplorerMap : public ExplorerMap {
 public:
  // y: #V+#F by 3. Keeps its own copy of the cage and y.
  CageExplorerMap(const Cage& cage, const MatX3d& y, std::string name, double fd_step = 1e-4);
  PolyJet jet(const Vec3& p) const override;
  Vec3 value(const Vec3& p) const override;
  Mat3 jacobian(const Vec3& p) const override;
  bool exact_third_derivatives() const override { return false; }
  std::string description() const override { return name_; }
  const Cage& cage() const { return cage_; }
  const MatX3d& coefficients() const { return y_; }
  const HarmonicBasis& basis() const { return basis_; }

 private:
  Cage cage_;
  MatX3d y_;
  HarmonicBasis basis_;
  std::string name_;
  double h_;
};

// σ's of the map at p with gradients and (with_hessian) Hessians and Laplacians
// (singular_value_derivatives.h).
SigmaDerivatives map_sigma_derivatives(const ExplorerMap& map, const Vec3& p, bool with_hessian = true);

}  // namespace lidef
