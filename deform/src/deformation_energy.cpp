#include "lidef/deformation_energy.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "lidef/blas_kernel.h"
#include "lidef/errors.h"
#include "lidef/internal/float_rows.h"
#include "lidef/internal/sd_lanes.h"
#include "lidef/symmetric_dirichlet.h"

namespace lidef {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Samples per chunk of the deterministic reductions: partial sums per chunk, added in chunk order.
constexpr int kChunk = 256;

Mat3 jacobian_at(const MatJT& JT, int i) {
  return JT.middleRows<3>(3 * i).transpose();
}

// The two passes over the stored float rows of G, the per-iteration stages that read the most memory: each
// float widened to double, every product and sum in double (G's rounding is the only one; the class comment),
// in SIMD lanes (float_rows.h); the summation order is fixed by the code, not by the thread count or a BLAS
// (deterministic).

// out(r, a) = Σ_j G(r, j) y(j, a) for rows [r0, r1) of G (row-major float, s columns), y: s by 3
// column-major (3 contiguous columns); out: column-major with leading dimension ld (JT's layout).
void rows_times(const MatXfR& G, int r0, int r1, const MatS3& y, double* out, Eigen::Index ld) {
  float_rows_times_columns(G.row(r0).data(), r1 - r0, y.data(), G.cols(),
                           [&](long k, double s0, double s1, double s2) {
                             const long r = r0 + k;
                             out[r] = s0, out[ld + r] = s1, out[2 * ld + r] = s2;
                           });
}

// acc(j, a) += Σ_r G(r, j) P(r − r0, a) for rows [r0, r1) of G; P: (r1 − r0) by 3 column-major with leading
// dimension ldp; acc: s by 3 column-major.
void rows_transpose_times(const MatXfR& G, int r0, int r1, const double* P, Eigen::Index ldp, MatS3& acc) {
  float_rows_transpose_times(
      G.row(r0).data(), r1 - r0, G.cols(), [&](long r, int a) { return P[a * ldp + r]; }, acc.data());
}

}  // namespace

DeformationEnergy::DeformationEnergy(MatXdR G, std::vector<int> hessian_subset, VecXd smooth_eigenvalues,
                                     int num_edges)
    : G_(G.cast<float>()),
      subset_(std::move(hessian_subset)),
      mu_(std::move(smooth_eigenvalues)),
      num_edges_(num_edges) {
  const int s = reduced_size();
  G.resize(0, 0);
  if (G_.rows() % 3 != 0 || G_.rows() == 0) throw Error("DeformationEnergy: G must have 3|I| > 0 rows");
  if (mu_.size() != s)
    throw Error("DeformationEnergy: one smoothness eigenvalue per reduced coefficient needed");
  if (num_edges_ <= 0) throw Error("DeformationEnergy: the cage has no edges");
  if (subset_.empty()) {
    subset_.resize(num_samples());
    for (int i = 0; i < num_samples(); ++i) subset_[i] = i;
  }
  for (int i : subset_)
    if (i < 0 || i >= num_samples()) throw Error("DeformationEnergy: Hessian subset index out of range");
  GH_.resize(3 * static_cast<Eigen::Index>(subset_.size()), s);
  for (size_t k = 0; k < subset_.size(); ++k) GH_.middleRows(3 * k, 3) = G_.middleRows(3 * subset_[k], 3);
  D_.setZero(0, s);
  Q_.setZero(0, 3);
  DtD_.setZero(s, s);
}

void DeformationEnergy::set_handles(const MatXd& D, const MatX3d& Q) {
  if (D.cols() != reduced_size() || D.rows() != Q.rows())
    throw Error("DeformationEnergy::set_handles: D must be #h by s and Q #h by 3");
  D_ = D;
  Q_ = Q;
  DtD_ = D_.transpose() * D_;
}

void DeformationEnergy::set_sample_weights(const VecXd& w) {
  if (w.size() == 0) {
    w_.resize(0);
    return;
  }
  if (w.size() != num_samples() || !(w.minCoeff() > 0) || !w.allFinite())
    throw Error("DeformationEnergy::set_sample_weights: one positive weight per sample needed");
  w_ = w * (num_samples() / w.sum());
}

void DeformationEnergy::set_targets(const MatX3d& Q) {
  if (Q.rows() != D_.rows()) throw Error("DeformationEnergy::set_targets: one target per handle needed");
  Q_ = Q;
}

MatJT DeformationEnergy::jacobians(const MatS3& y) const {
  MatJT JT(G_.rows(), 3);
  const int n = num_samples();
  const int chunks = (n + kChunk - 1) / kChunk;
#pragma omp parallel for schedule(static)
  for (int c = 0; c < chunks; ++c) {
    const int b = c * kChunk, e = std::min(n, b + kChunk);
    rows_times(G_, 3 * b, 3 * e, y, JT.data(), JT.rows());
  }
  return JT;
}

MatX3d DeformationEnergy::handle_positions(const MatS3& y) const {
  return D_ * y;
}

VecXd DeformationEnergy::handle_errors(const MatS3& y) const {
  return (handle_positions(y) - Q_).rowwise().norm();
}

double DeformationEnergy::sample_weight(int i) const {
  return w_.size() ? w_(i) : 1.0;
}

template <class PerLanes>
double DeformationEnergy::weighted_lane_sum(const PerLanes& per_lanes) const {
  const int n = num_samples();
  const int chunks = (n + kChunk - 1) / kChunk;
  std::vector<double> partial(chunks, 0.0);
#pragma omp parallel for schedule(static)
  for (int c = 0; c < chunks; ++c) {
    const int b = c * kChunk, e = std::min(n, b + kChunk);
    double v[kChunk];
    for (int i = b; i < e; i += 4) {
      const sd_lanes::Lanes l = per_lanes(i, e - 1);
      for (int k = 0; k < 4 && i + k < e; ++k) v[i - b + k] = l[k];
    }
    double sum = 0;
    for (int i = b; i < e; ++i) sum += sample_weight(i) * v[i - b];
    partial[c] = sum;
  }
  double total = 0;
  for (double p : partial) total += p;  // chunk order: deterministic
  return total;
}

double DeformationEnergy::distortion_sum(const MatJT& JT) const {
  return weighted_lane_sum([&](int first, int last) {
    sd_lanes::Mat3Lanes J;
    sd_lanes::load(JT.data(), JT.rows(), first, last, J);
    return sd_lanes::energy(J) - 6.0;
  });
}

EnergyTerms DeformationEnergy::terms(double dis_sum, const MatS3& y, const EnergyWeights& w) const {
  EnergyTerms t;
  t.dis = dis_sum / num_samples();
  t.p2p = D_.rows() > 0 ? (D_ * y - Q_).squaredNorm() : 0.0;
  t.smooth = (mu_.asDiagonal() * y).cwiseProduct(y).sum() / num_edges_;
  t.total = std::isfinite(t.dis) ? t.dis + w.p2p * t.p2p + w.smooth * t.smooth : kInf;
  return t;
}

EnergyTerms DeformationEnergy::evaluate(const MatJT& JT, const MatS3& y, const EnergyWeights& w) const {
  return terms(distortion_sum(JT), y, w);
}

MatS3 DeformationEnergy::distortion_gradient_sum(const MatJT& JT) const {
  return weighted_transpose_lanes([&](int first, int last, sd_lanes::Mat3Lanes g) {
    sd_lanes::Mat3Lanes J;
    sd_lanes::load(JT.data(), JT.rows(), first, last, J);
    sd_lanes::gradient(J, g);
  });
}

MatS3 DeformationEnergy::weighted_transpose_times(const MatJT& T) const {
  return weighted_transpose_sum([&](int i) { return jacobian_at(T, i); });
}

MatS3 DeformationEnergy::distortion_hessian_times_sum(const MatJT& JT, const MatJT& dJ) const {
  return weighted_transpose_sum(
      [&](int i) { return sd_hessian_times(jacobian_at(JT, i), jacobian_at(dJ, i)); });
}

double DeformationEnergy::distortion_curvature(const MatJT& JT, const MatJT& dJ) const {
  return weighted_lane_sum([&](int first, int last) {
    sd_lanes::Mat3Lanes J, D;
    sd_lanes::load(JT.data(), JT.rows(), first, last, J);
    sd_lanes::load(dJ.data(), dJ.rows(), first, last, D);
    return sd_lanes::curvature(J, D);
  });
}

template <class Fill>
MatS3 DeformationEnergy::transpose_sum(const Fill& fill) const {
  const int n = num_samples(), s = reduced_size();
  const int chunks = (n + kChunk - 1) / kChunk;
  std::vector<MatS3> partial(chunks);
#pragma omp parallel for schedule(static)
  for (int c = 0; c < chunks; ++c) {
    const int b = c * kChunk, e = std::min(n, b + kChunk);
    MatJT P(3 * (e - b), 3);
    fill(b, e, P);
    partial[c].setZero(s, 3);
    rows_transpose_times(G_, 3 * b, 3 * e, P.data(), P.rows(), partial[c]);
  }
  MatS3 g = MatS3::Zero(s, 3);
  for (const MatS3& p : partial) g += p;
  return g;
}

template <class PerSample>
MatS3 DeformationEnergy::weighted_transpose_sum(const PerSample& per_sample) const {
  return transpose_sum([&](int b, int e, MatJT& P) {
    for (int i = b; i < e; ++i) P.middleRows<3>(3 * (i - b)) = sample_weight(i) * per_sample(i).transpose();
  });
}

template <class PerLanes>
MatS3 DeformationEnergy::weighted_transpose_lanes(const PerLanes& per_lanes) const {
  return transpose_sum([&](int b, int e, MatJT& P) {
    for (int i = b; i < e; i += 4) {
      sd_lanes::Mat3Lanes m;
      per_lanes(i, e - 1, m);
      for (int k = 0; k < 4 && i + k < e; ++k) {
        const double w = sample_weight(i + k);
        for (int a = 0; a < 3; ++a)
          for (int r = 0; r < 3; ++r) P(3 * (i - b + k) + r, a) = w * m[a][r][k];
      }
    }
  });
}

MatS3 DeformationEnergy::quadratic_hessian_times(const MatS3& d, const EnergyWeights& w) const {
  MatS3 h = (2.0 * w.smooth / num_edges_) * (mu_.asDiagonal() * d);
  if (D_.rows() > 0) h.noalias() += (2.0 * w.p2p) * (DtD_ * d);
  return h;
}

MatS3 DeformationEnergy::gradient_from(const MatS3& dis_sum, const MatS3& y, const EnergyWeights& w) const {
  MatS3 g = dis_sum / num_samples();
  if (D_.rows() > 0) g.noalias() += 2.0 * w.p2p * D_.transpose() * (D_ * y - Q_);
  g += (2.0 * w.smooth / num_edges_) * (mu_.asDiagonal() * y);
  return g;
}

MatS3 DeformationEnergy::gradient(const MatJT& JT, const MatS3& y, const EnergyWeights& w) const {
  return gradient_from(distortion_gradient_sum(JT), y, w);
}

VecXd DeformationEnergy::subset_block_weights() const {
  // select_hessian_subset picks one sample per stratum of equal volume (equal count on the uniform grid), a
  // sample with a probability proportional to its volume: each pick stands for the same volume W/m, so the
  // estimate of Σ_i w_i H_i / Σ_i w_i is the plain mean of the picks' blocks. Weighing the picks by w_i as
  // well counted the volume twice (a level-0 leaf's block weighed 512 times a level-3 leaf's): on the refined
  // beam its relative error was 0.72 against 0.09 (DomainEnergy.HessianSubsetOfARefinedDomainEstimates...).
  const int m = static_cast<int>(subset_.size());
  return VecXd::Constant(m, 1.0 / m);
}

VecXd DeformationEnergy::all_block_weights() const {
  const int n = num_samples();
  if (w_.size() == 0) return VecXd::Constant(n, 1.0 / n);
  return w_ / w_.sum();
}

std::vector<Mat9> DeformationEnergy::sample_blocks(const MatJT& JT, const std::vector<int>& idx,
                                                   const VecXd& weight, bool projected) const {
  const int m = static_cast<int>(idx.size());
  std::vector<Mat9> blocks(m);
#pragma omp parallel for schedule(static)
  for (int k = 0; k < m; ++k) {
    const Mat3 J = jacobian_at(JT, idx[k]);
    blocks[k] = weight(k) * (projected ? sd_hessian_psd(J) : sd_hessian(J));
  }
  return blocks;
}

std::vector<Mat9> DeformationEnergy::subset_hessian_blocks(const MatJT& JT) const {
  return sample_blocks(JT, subset_, subset_block_weights(), true);
}

MatS3 DeformationEnergy::subset_hessian_times(const std::vector<Mat9>& blocks, const MatS3& d) const {
  const int m = static_cast<int>(subset_.size()), s = reduced_size();
  if (static_cast<int>(blocks.size()) != m)
    throw Error("subset_hessian_times: one block per subset sample needed");
  // One pass over G_H: per sample k its three float rows G_k give dJ_k = dᵀ G_kᵀ (dJ_k(a, b) = G_k.row(b) ·
  // d.col(a)), then B_k vec(dJ_k) (vec order a + 3b) is added back as G_kᵀ P_k while the rows are in cache
  // (float_rows.h). All arithmetic in double: the CG steps need an operator that is linear to working
  // precision (single-precision sums round differently for every direction, and CG amplifies that). Fixed
  // chunks summed in order: the same bits for every thread count. The subset has few chunks (6–7 at the
  // defaults), so they are dealt out one at a time: with 7 (bar_bend), contiguous blocks gave one of two
  // threads twice the other's samples (docs/benchmarks.md, "The subset Hessian's product on two threads").
  const int chunks = (m + kChunk - 1) / kChunk;
  std::vector<MatS3> partial(chunks);
#pragma omp parallel for schedule(static, 1)
  for (int c = 0; c < chunks; ++c) {
    MatS3 acc = MatS3::Zero(s, 3);
    for (int k = c * kChunk; k < std::min(m, (c + 1) * kChunk); ++k) {
      const float* Gk = GH_.data() + 3 * static_cast<Eigen::Index>(k) * s;
      Eigen::Matrix<double, 9, 1> v;
      float_rows_times_columns(Gk, 3, d.data(), s, [&v](long b, double s0, double s1, double s2) {
        v(3 * b) = s0, v(1 + 3 * b) = s1, v(2 + 3 * b) = s2;
      });
      const Eigen::Matrix<double, 9, 1> hv = blocks[k] * v;
      const double q[3][3] = {{hv(0), hv(1), hv(2)}, {hv(3), hv(4), hv(5)}, {hv(6), hv(7), hv(8)}};
      float_rows_transpose_times_group<3>(Gk, q, s, acc.data());
    }
    partial[c] = std::move(acc);
  }
  MatS3 out = MatS3::Zero(s, 3);
  for (const MatS3& p : partial) out += p;
  return out;
}

MatXd DeformationEnergy::pair_blocks(const MatJT& JT, bool projected, bool all_samples,
                                     bool double_precision) const {
  const std::vector<int>* idx = &subset_;
  std::vector<int> all;
  if (all_samples) {
    all.resize(num_samples());
    for (int i = 0; i < num_samples(); ++i) all[i] = i;
    idx = &all;
  }
  // Per-sample 9x9 blocks (weighted), in vec(J) order a + 3b.
  const VecXd weight = all_samples ? all_block_weights() : subset_block_weights();
  return products(sample_blocks(JT, *idx, weight, projected), all_samples, double_precision);
}

MatXd DeformationEnergy::distortion_pair_blocks_from(const std::vector<Mat9>& blocks,
                                                     bool double_precision) const {
  if (blocks.size() != subset_.size())
    throw Error("distortion_pair_blocks_from: one block per subset sample needed");
  return products(blocks, false, double_precision);
}

MatXd DeformationEnergy::products(const std::vector<Mat9>& blocks, bool all_samples,
                                  bool double_precision) const {
  const int s = reduced_size();
  const int m = static_cast<int>(blocks.size());
  // The six (a ≤ a') blocks: W = [diag_k(H̃_k^{aa'}) G_k]_{(a,a')} side by side (3m by 6s), then one product
  // G_Hᵀ W (s by 6s) — one large BLAS call blocks and threads better than six small ones.
  constexpr int kPairs[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
  auto pair_block = [&](const Mat9& Hk, int q) {
    const int a = kPairs[q][0], a2 = kPairs[q][1];
    Mat3 Ht;
    for (int b = 0; b < 3; ++b)
      for (int b2 = 0; b2 < 3; ++b2) Ht(b, b2) = Hk(a + 3 * b, a2 + 3 * b2);
    return Ht;
  };
  MatXd Ball(s, 6 * s);
  if (all_samples || double_precision) {
    // Double precision: the reference over all samples (idx = 0..n-1, so G's rows match W's), or the subset
    // for parity checks between backends, where single-precision rounding of the direction (~1e-7) would hide
    // everything else.
    MatXdR W(3 * static_cast<Eigen::Index>(m), 6 * s);
    const MatXdR Gd = all_samples ? MatXdR(G_.cast<double>()) : MatXdR(GH_.cast<double>());
#pragma omp parallel for schedule(static)
    for (int k = 0; k < m; ++k)
      for (int q = 0; q < 6; ++q) {
        const Mat3 Ht = pair_block(blocks[k], q);
        for (int b = 0; b < 3; ++b)  // row combinations (a 3x3 times 3 x s product; see the float branch)
          W.block(3 * k + b, q * s, 1, s) =
              Ht(b, 0) * Gd.row(3 * k) + Ht(b, 1) * Gd.row(3 * k + 1) + Ht(b, 2) * Gd.row(3 * k + 2);
      }
    gemm_parallel(false, true, s, 6 * s, 3 * m, Gd.data(), s, W.data(), 6 * s, Ball.data(), s);
  } else {
    // Row-major: the rows written below are contiguous. W (3m x 6s, ~30 MB at the defaults) and Bf are kept
    // per calling thread and overwritten in full each time: a fresh allocation of that size costs page faults
    // in every iteration until malloc's mmap threshold has grown (and, with huge pages, at times a compaction
    // stall), which was most of the first iterations' Hessian time.
    // (References: inside the parallel loop a thread_local name would be each worker's own.)
    thread_local MatXfR kept_W;
    thread_local Eigen::MatrixXf kept_Bf;
    MatXfR& W = kept_W;
    Eigen::MatrixXf& Bf = kept_Bf;
    W.resize(3 * static_cast<Eigen::Index>(m), 6 * s);
#pragma omp parallel for schedule(static)
    for (int k = 0; k < m; ++k)
      for (int q = 0; q < 6; ++q) {
        const Mat3 Ht = pair_block(blocks[k], q);
        // Written as row combinations: Eigen's fixed 3x3 product kernel trips GCC 12's -Warray-bounds under
        // AVX.
        for (int b = 0; b < 3; ++b)
          W.block(3 * k + b, q * s, 1, s) = static_cast<float>(Ht(b, 0)) * GH_.row(3 * k) +
                                            static_cast<float>(Ht(b, 1)) * GH_.row(3 * k + 1) +
                                            static_cast<float>(Ht(b, 2)) * GH_.row(3 * k + 2);
      }
    Bf.resize(s, 6 * s);
    // Row-major GH (3m x s) is column-major GHᵀ (s x 3m); row-major W is column-major Wᵀ.
    gemm_parallel(false, true, s, 6 * s, 3 * m, GH_.data(), s, W.data(), 6 * s, Bf.data(), s);
    Ball = Bf.cast<double>();
  }
  return Ball;
}

namespace {
// 3s by 3s from the six pair blocks (s by 6s), exactly symmetric.
MatXd assemble_pairs(const MatXd& Ball) {
  const int s = static_cast<int>(Ball.rows());
  // Column q*s + j of Ball is column j of the pair block q = (a, a2), a <= a2.
  constexpr int kPair[3][3] = {{0, 1, 2}, {1, 3, 4}, {2, 4, 5}};
  MatXd H(3 * s, 3 * s);
  // Exactly symmetric in one pass: H = ½(H₀ + H₀ᵀ) of the block matrix H₀ (pair blocks above and on the
  // diagonal, their transposes below), written element by element. Off the diagonal blocks that is the pair
  // block itself (½(x + x) = x exactly); on them ½(B(i, j) + B(j, i)) (float products of GHᵀ W are symmetric
  // only up to rounding). No temporary 3s x 3s matrix; columns are independent, so the threads do not change
  // a bit.
#pragma omp parallel for schedule(static)
  for (int col = 0; col < 3 * s; ++col) {
    const int a2 = col / s, j = col % s;
    for (int a = 0; a < 3; ++a) {
      const int q = kPair[a][a2];
      double* out = H.data() + static_cast<Eigen::Index>(col) * 3 * s + a * s;
      const double* column = Ball.data() + (static_cast<Eigen::Index>(q) * s + j) * s;
      if (a < a2) {
        std::memcpy(out, column, sizeof(double) * s);
      } else if (a > a2) {
        for (int i = 0; i < s; ++i) out[i] = Ball(j, q * s + i);
      } else {
        for (int i = 0; i < s; ++i) out[i] = 0.5 * (column[i] + Ball(j, q * s + i));
      }
    }
  }
  return H;
}
}  // namespace

MatXd DeformationEnergy::distortion_hessian(const MatJT& JT, bool projected, bool all_samples) const {
  return assemble_pairs(pair_blocks(JT, projected, all_samples, false));
}

MatXd DeformationEnergy::distortion_pair_blocks(const MatJT& JT, bool double_precision) const {
  return pair_blocks(JT, true, false, double_precision);
}

MatXd DeformationEnergy::hessian(const MatJT& JT, const EnergyWeights& w, bool projected,
                                 bool all_samples) const {
  MatXd H = distortion_hessian(JT, projected, all_samples);
  add_quadratic_hessian(H, w);
  return H;
}

MatXd DeformationEnergy::hessian_from(const MatXd& pair_blocks, const EnergyWeights& w) const {
  MatXd H = assemble_pairs(pair_blocks);
  add_quadratic_hessian(H, w);
  return H;
}

void DeformationEnergy::add_quadratic_hessian(MatXd& H, const EnergyWeights& w) const {
  const int s = reduced_size();
  for (int a = 0; a < 3; ++a) {
    auto blk = H.block(a * s, a * s, s, s);
    if (D_.rows() > 0) blk += (2.0 * w.p2p) * DtD_;
    blk.diagonal() += (2.0 * w.smooth / num_edges_) * mu_;
  }
}

}  // namespace lidef
