#include "lidef/smoothness.h"

#include <string>
#include <vector>

#include "lidef/errors.h"

namespace lidef {

namespace {

// The 4 coefficient rows that face t reads and the vectors c_k with A_t = Σ_k y_k c_kᵀ:
// rows[0..2] are t's vertices (c = ∇λ_v), rows[3] is t's face row (c = n_t).
struct FaceStencil {
  int rows[4];
  Vec3 c[4];
};

FaceStencil face_stencil(const Cage& cage, int t) {
  FaceStencil s;
  const Vec3 n = cage.N.row(t).transpose();
  const double inv2s = 1.0 / (2.0 * cage.area(t));
  for (int k = 0; k < 3; ++k) {
    // ∇λ of vertex k is n × (opposite edge, traversed in cage order) / (2 s): it points from that edge
    // towards vertex k with length 1/height, so Σ_k ∇λ_k = 0 and ∇λ_k · (x_j − x_k) = −1 for j ≠ k.
    const Vec3 e_from = cage.V.row(cage.F(t, (k + 1) % 3)).transpose();
    const Vec3 e_to = cage.V.row(cage.F(t, (k + 2) % 3)).transpose();
    s.rows[k] = cage.F(t, k);
    s.c[k] = n.cross(e_to - e_from) * inv2s;
  }
  s.rows[3] = cage.num_vertices() + t;
  s.c[3] = n;
  return s;
}

void check_y(const Cage& cage, const MatX3d& y, const char* what) {
  if (y.rows() != cage.num_coeffs())
    throw InputError(cage.source, std::string(what) + ": coefficients have " + std::to_string(y.rows()) +
                                      " rows, the cage needs #V+#F = " + std::to_string(cage.num_coeffs()));
}

}  // namespace

Mat3 face_affine_matrix(const Cage& cage, const MatX3d& y, int t) {
  check_y(cage, y, "face_affine_matrix");
  if (t < 0 || t >= cage.num_faces())
    throw InputError(cage.source, "face_affine_matrix: face index " + std::to_string(t) +
                                      " out of range [0," + std::to_string(cage.num_faces()) + ")");
  const FaceStencil s = face_stencil(cage, t);
  Mat3 A = Mat3::Zero();
  for (int k = 0; k < 4; ++k) A += y.row(s.rows[k]).transpose() * s.c[k].transpose();
  return A;
}

Eigen::SparseMatrix<double> smoothness_matrix(const Cage& cage) {
  const int ne = cage.num_edges();
  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(static_cast<size_t>(ne) * 24);
  for (int e = 0; e < ne; ++e) {
    const CageEdge& E = cage.edges[e];
    const FaceStencil s0 = face_stencil(cage, E.f0), s1 = face_stencil(cage, E.f1);
    // (A_tᵀ)(i, j) = Σ_k c_k(i) y(k, j): row i of A_tᵀ is the row vector (c_k(i))_k applied to y.
    // The two shared vertices appear in both stencils; setFromTriplets sums the duplicates.
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 4; ++k) {
        trip.emplace_back(3 * e + i, s0.rows[k], s0.c[k](i));
        trip.emplace_back(3 * e + i, s1.rows[k], -s1.c[k](i));
      }
  }
  Eigen::SparseMatrix<double> K(3 * ne, cage.num_coeffs());
  K.setFromTriplets(trip.begin(), trip.end());
  return K;
}

VecXd edge_delta_norms(const Cage& cage, const Eigen::SparseMatrix<double>& K, const MatX3d& y) {
  check_y(cage, y, "edge_delta_norms");
  if (K.rows() != 3 * cage.num_edges() || K.cols() != cage.num_coeffs())
    throw InputError(cage.source, "edge_delta_norms: K is " + std::to_string(K.rows()) + " by " +
                                      std::to_string(K.cols()) +
                                      ", expected 3#E = " + std::to_string(3 * cage.num_edges()) +
                                      " by #V+#F = " + std::to_string(cage.num_coeffs()));
  const MatX3d Ky = K * y;
  VecXd out(cage.num_edges());
  for (int e = 0; e < cage.num_edges(); ++e) out(e) = Ky.middleRows<3>(3 * e).norm();
  return out;
}

double smoothness_energy(const Eigen::SparseMatrix<double>& K, const MatX3d& y) {
  if (K.cols() != y.rows())
    throw InputError("", "smoothness_energy: K has " + std::to_string(K.cols()) + " columns but y has " +
                             std::to_string(y.rows()) + " rows");
  return (K * y).squaredNorm();
}

}  // namespace lidef
