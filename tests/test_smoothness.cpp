// Tests of the smoothness operator K (paper Sec. 6.1) and of the per-face affine matrices A_t (Lemma 5.1).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>

#include "lidef/cage.h"
#include "lidef/errors.h"
#include "lidef/mesh_io.h"
#include "lidef/smoothness.h"
#include "test_support.h"

namespace lidef {
namespace {

// Axis-aligned box [0,sx]x[0,sy]x[0,sz], 12 triangles, CCW seen from outside.
TriMesh box_mesh(double sx, double sy, double sz) {
  TriMesh m;
  m.V.resize(8, 3);
  for (int i = 0; i < 8; ++i) m.V.row(i) << (i & 1 ? sx : 0), (i & 2 ? sy : 0), (i & 4 ? sz : 0);
  m.F.resize(12, 3);
  m.F << 0, 2, 3, 0, 3, 1,  // z = 0 (normal -z)
      4, 5, 7, 4, 7, 6,     // z = sz
      0, 1, 5, 0, 5, 4,     // y = 0
      2, 6, 7, 2, 7, 3,     // y = sy
      0, 4, 6, 0, 6, 2,     // x = 0
      1, 3, 7, 1, 7, 5;     // x = sx
  m.source = "box";
  return m;
}

// Genus-1 cage: a torus (radii R, r) of nu x nv quads, each split in two, oriented outward.
TriMesh torus_mesh(int nu, int nv, double R, double r) {
  TriMesh m;
  m.V.resize(nu * nv, 3);
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const double u = 2 * M_PI * i / nu, v = 2 * M_PI * j / nv;
      m.V.row(i * nv + j) << (R + r * std::cos(v)) * std::cos(u), (R + r * std::cos(v)) * std::sin(u),
          r * std::sin(v);
    }
  m.F.resize(2 * nu * nv, 3);
  int f = 0;
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const int a = i * nv + j, b = ((i + 1) % nu) * nv + j, c = ((i + 1) % nu) * nv + (j + 1) % nv,
                d = i * nv + (j + 1) % nv;
      m.F.row(f++) << a, b, c;
      m.F.row(f++) << a, c, d;
    }
  m.source = "torus";
  Cage probe(m);
  if (probe.volume < 0) m.F.col(1).swap(m.F.col(2));
  return m;
}

std::vector<Cage> test_cages() {
  std::vector<Cage> out = {Cage(box_mesh(1.0, 0.7, 1.3)), Cage(torus_mesh(12, 8, 1.0, 0.35))};
  if (!test::shared_data().empty())
    for (const char* name : {"bar", "horse", "spot", "animal"})
      out.emplace_back(read_mesh(test::shared_model(name) + "/cage.obj"));
  return out;
}

Mat3 random_matrix(std::mt19937& rng) {
  std::normal_distribution<double> N(0.0, 1.0);
  Mat3 A;
  for (int i = 0; i < 9; ++i) A(i) = N(rng);
  return A;
}

MatX3d random_coeffs(const Cage& cage, std::mt19937& rng) {
  std::normal_distribution<double> N(0.0, 1.0);
  MatX3d y(cage.num_coeffs(), 3);
  for (Eigen::Index i = 0; i < y.size(); ++i) y.data()[i] = N(rng);
  return y;
}

// Lemma 5.1 exactly as the paper prints it: A_t = y_t n_tᵀ − 1/(2 s_t) Σ_v y_v (n_t × d_v)ᵀ, with
// d_v = w − u for (u, v, w) consecutive in the face's cage order.
Mat3 printed_lemma_5_1(const Cage& cage, const MatX3d& y, int t) {
  const Vec3 n = cage.N.row(t);
  Mat3 A = y.row(cage.num_vertices() + t).transpose() * n.transpose();
  for (int k = 0; k < 3; ++k) {
    const int u = cage.F(t, (k + 2) % 3), v = cage.F(t, k), w = cage.F(t, (k + 1) % 3);
    const Vec3 d = cage.V.row(w) - cage.V.row(u);
    A -= y.row(v).transpose() * n.cross(d).transpose() / (2 * cage.area(t));
  }
  return A;
}

TEST(Smoothness, EdgeCountFollowsEulerForAnyGenus) {
  const Cage box(box_mesh(1, 1, 1)), torus(torus_mesh(12, 8, 1.0, 0.35));
  EXPECT_EQ(box.num_edges(), box.num_vertices() + box.num_faces() - 2);    // genus 0
  EXPECT_EQ(torus.num_edges(), torus.num_vertices() + torus.num_faces());  // genus 1: χ = 0
  const auto K = smoothness_matrix(torus);
  EXPECT_EQ(K.rows(), 3 * torus.num_edges());
  EXPECT_EQ(K.cols(), torus.num_coeffs());
}

TEST(Smoothness, FaceMatrixOfAffineCoefficientsIsTheAffineMatrix) {
  std::mt19937 rng(11);
  for (const Cage& cage : test_cages()) {
    for (int trial = 0; trial < 3; ++trial) {
      const Mat3 A = random_matrix(rng);
      const Vec3 b = random_matrix(rng).col(0);
      const MatX3d y = cage.affine_coefficients(A, b);
      double worst = 0;
      for (int t = 0; t < cage.num_faces(); ++t)
        worst = std::max(worst, (face_affine_matrix(cage, y, t) - A).norm());
      EXPECT_LT(worst, 1e-12 * A.norm()) << cage.source;
    }
  }
}

// Appendix C: A_t maps n_t to y_t and each edge x_j − x_i of t to y_j − y_i, for arbitrary y; and it agrees
// with the printed formula (d_v = w − u, minus sign).
TEST(Smoothness, FaceMatrixSatisfiesLemmaConditionsForArbitraryCoefficients) {
  std::mt19937 rng(12);
  for (const Cage& cage : test_cages()) {
    const MatX3d y = random_coeffs(cage, rng);
    double worst = 0, worst_printed = 0;
    for (int t = 0; t < cage.num_faces(); ++t) {
      const Mat3 At = face_affine_matrix(cage, y, t);
      worst = std::max(worst,
                       (At * cage.N.row(t).transpose() - y.row(cage.num_vertices() + t).transpose()).norm());
      for (int k = 0; k < 3; ++k) {
        const int i = cage.F(t, k), j = cage.F(t, (k + 1) % 3);
        const Vec3 dx = cage.V.row(j) - cage.V.row(i);
        const Vec3 dy = y.row(j) - y.row(i);
        worst = std::max(worst, (At * dx - dy).norm());
      }
      worst_printed = std::max(worst_printed, (At - printed_lemma_5_1(cage, y, t)).norm() / At.norm());
    }
    EXPECT_LT(worst, 1e-9) << cage.source;  // y ~ N(0,1); A_t ~ 1/edge length
    EXPECT_LT(worst_printed, 1e-12) << cage.source;
  }
}

TEST(Smoothness, KRowsAreTransposedFaceMatrixJumps) {
  std::mt19937 rng(13);
  for (const Cage& cage : test_cages()) {
    const auto K = smoothness_matrix(cage);
    const MatX3d y = random_coeffs(cage, rng);
    const MatX3d Ky = K * y;
    double worst = 0, scale = 0;
    for (int e = 0; e < cage.num_edges(); ++e) {
      const Mat3 delta =
          face_affine_matrix(cage, y, cage.edges[e].f0) - face_affine_matrix(cage, y, cage.edges[e].f1);
      worst = std::max(worst, (Ky.middleRows<3>(3 * e) - delta.transpose()).norm());
      scale = std::max(scale, delta.norm());
    }
    EXPECT_LT(worst, 1e-13 * scale) << cage.source;
    EXPECT_GT(scale, 1e-3) << cage.source;  // random y is far from affine
  }
}

TEST(Smoothness, KVanishesExactlyOnAffineMaps) {
  std::mt19937 rng(14);
  for (const Cage& cage : test_cages()) {
    const auto K = smoothness_matrix(cage);
    const double kscale = K.norm();
    for (int trial = 0; trial < 4; ++trial) {
      const Mat3 A = trial == 0 ? Mat3::Identity() : random_matrix(rng);
      const MatX3d y = cage.affine_coefficients(A, random_matrix(rng).col(0));
      const double rel = (K * y).norm() / (kscale * y.norm());
      EXPECT_LT(rel, 1e-14) << cage.source << " trial " << trial;
      EXPECT_LT(edge_delta_norms(cage, K, y).maxCoeff(), 1e-11 * A.norm()) << cage.source;
    }
    // A non-affine y: affine plus a bump on one vertex. δ changes exactly on the edges whose faces touch it.
    MatX3d y = cage.identity_coefficients();
    const int v0 = cage.num_vertices() / 2;
    y.row(v0) += Eigen::RowVector3d(0.01, -0.02, 0.015);
    const VecXd d = edge_delta_norms(cage, K, y);
    // (An edge whose both faces hold v0 may still see no jump: on coplanar faces whose far vertices are
    // collinear with the edge's other end, v0's hat function is linear across the edge.)
    int touched = 0;
    for (int e = 0; e < cage.num_edges(); ++e) {
      const auto& E = cage.edges[e];
      const bool near = (cage.F.row(E.f0).array() == v0).any() || (cage.F.row(E.f1).array() == v0).any();
      if (near)
        touched += d(e) > 1e-4;
      else
        EXPECT_LT(d(e), 1e-12) << cage.source << " edge " << e;
    }
    EXPECT_GE(touched, 3) << cage.source;
    EXPECT_GT(smoothness_energy(K, y), 0.0);
  }
}

// The null space of K (acting on one coefficient column) is exactly 4-dimensional: only affine maps are
// smooth. Independent check by a dense SVD, including the genus-1 cage.
TEST(Smoothness, NullSpaceIsExactlyTheAffineMaps) {
  std::vector<Cage> cages = {Cage(box_mesh(1.0, 0.7, 1.3)), Cage(torus_mesh(12, 8, 1.0, 0.35))};
  if (!test::shared_data().empty()) cages.emplace_back(read_mesh(test::shared_model("bar") + "/cage.obj"));
  for (const Cage& cage : cages) {
    const Eigen::MatrixXd K = Eigen::MatrixXd(smoothness_matrix(cage));
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(K);
    const VecXd sv = svd.singularValues();
    const int n = static_cast<int>(sv.size());
    int zeros = 0;
    for (int i = 0; i < n; ++i) zeros += sv(i) < 1e-10 * sv(0);
    EXPECT_EQ(zeros, 4) << cage.source << " smallest nonzero singular value " << sv(n - 5) / sv(0);
  }
}

TEST(Smoothness, DeltaNormsUnderAffineComposition) {
  std::mt19937 rng(15);
  for (const Cage& cage : test_cages()) {
    const auto K = smoothness_matrix(cage);
    const MatX3d y = random_coeffs(cage, rng);
    const VecXd d0 = edge_delta_norms(cage, K, y);
    const int nv = cage.num_vertices();

    // f ↦ R f + t (rigid): y ↦ y Rᵀ on all rows, + t on vertex rows. δ ↦ R δ, norms unchanged.
    const Mat3 R = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
    MatX3d yr = y * R.transpose();
    yr.topRows(nv).rowwise() += Eigen::RowVector3d(0.3, -1.0, 2.0);
    EXPECT_LT((edge_delta_norms(cage, K, yr) - d0).cwiseAbs().maxCoeff(), 1e-12 * d0.maxCoeff())
        << cage.source;

    // Adding an affine map's coefficients leaves every δ unchanged (K y_affine = 0).
    const MatX3d ya = y + cage.affine_coefficients(random_matrix(rng), Vec3(1, 2, 3));
    EXPECT_LT((K * ya - K * y).norm(), 1e-12 * (K * y).norm()) << cage.source;

    // A general linear B (a shear): δ ↦ B δ, so the norms change, exactly as ‖B δ‖.
    Mat3 B = Mat3::Identity();
    B(0, 1) = 1.5;
    MatX3d yb = y * B.transpose();
    yb.topRows(nv).rowwise() += Eigen::RowVector3d(5, 5, 5);
    const VecXd db = edge_delta_norms(cage, K, yb);
    const MatX3d Ky = K * y;
    double worst = 0;
    for (int e = 0; e < cage.num_edges(); ++e) {
      const Mat3 delta = Ky.middleRows<3>(3 * e).transpose();
      worst = std::max(worst, std::abs(db(e) - (B * delta).norm()));
    }
    EXPECT_LT(worst, 1e-12 * db.maxCoeff()) << cage.source;
    EXPECT_GT((db - d0).cwiseAbs().maxCoeff(), 0.1 * d0.maxCoeff()) << cage.source;
  }
}

TEST(Smoothness, RejectsMismatchedShapes) {
  const Cage cage(box_mesh(1, 1, 1));
  const auto K = smoothness_matrix(cage);
  EXPECT_THROW(face_affine_matrix(cage, MatX3d::Zero(3, 3), 0), InputError);
  EXPECT_THROW(face_affine_matrix(cage, cage.identity_coefficients(), cage.num_faces()), InputError);
  EXPECT_THROW(edge_delta_norms(cage, K, MatX3d::Zero(5, 3)), InputError);
}

}  // namespace
}  // namespace lidef
