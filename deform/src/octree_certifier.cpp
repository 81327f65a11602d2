#include "lidef/octree_certifier.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <iterator>
#include <limits>
#include <mutex>
#include <numeric>

#include "lidef/blas_kernel.h"
#include "lidef/errors.h"
#include "lidef/internal/edge_jet.h"
#include "lidef/internal/enum_names.h"
#include "lidef/internal/float_rows.h"
#include "lidef/internal/jacobi_singular_values.h"
#include "lidef/internal/mesh_queries.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/lipschitz_bound.h"
#include "lidef/number_format.h"
#include "lidef/signed_svd.h"

namespace lidef {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Full 27-entry Frobenius norm of a Hessian tensor given as 3 symmetric 6-entry rows (xx,xy,xz,yy,yz,zz).
inline double hessian_norm_sym(const double* h0, int stride_a) {
  double s = 0;
  for (int a = 0; a < 3; ++a) {
    const double* h = h0 + a * stride_a;
    s += h[0] * h[0] + h[3] * h[3] + h[5] * h[5] + 2 * (h[1] * h[1] + h[2] * h[2] + h[4] * h[4]);
  }
  return std::sqrt(s);
}

}  // namespace

std::vector<char> balls_clear_of_cage(const Cage& cage, const VoxelSampling& s) {
  const long N = s.size();
  std::vector<char> out(N, 0);
  if (N == 0) return out;
  const TriangleGrid grid(cage.V, cage.F,
                          std::max(s.radius(), (cage.bbox_max - cage.bbox_min).norm() / 128.0));
  const WindingNumber wn(cage.V, cage.F);
  // "Clear" is strict, with a relative margin far above the rounding of the distance computation.
#pragma omp parallel for schedule(dynamic, 256)
  for (long i = 0; i < N; ++i) {
    const Vec3 c = s.centers.row(i);
    const double r = s.radius_of(static_cast<int>(i));
    out[i] = c.allFinite() && !grid.any_within(c, r * (1 + 1e-9)) && std::abs(wn.at(c) - 1.0) < 1e-6;
  }
  return out;
}

struct OctreeCertifier::Impl {
  enum class Mode { kReduced, kFull, kOnTheFly } mode = Mode::kOnTheFly;
  const MatXd* reduction = nullptr;  // #V+#F by s
  // Basis derivatives at the centers in the coefficient space (m = s or #V+#F), unless on the fly: per voxel
  // one contiguous block of 9 rows of m floats — the 3 gradient rows (∂/∂x, ∂/∂y, ∂/∂z), then the 6 Hessian
  // rows (xx,xy,xz,yy,yz,zz) — so one certification streams the array once. Float halves the bytes of this
  // bandwidth-bound stage; the storage rounding is covered by the allowance kFloatStorageRel (see run()).
  std::vector<float> GH;
  long m = 0;
  VecXd scale_J, scale_H;    // per voxel: Σ over the rows and k of |stored value| (rounding allowance)
  std::vector<Vec3> eu, ew;  // endpoints of each undirected edge
  // Lazily computed per-voxel per-edge bound factors (|I| by #E, row-major).
  mutable std::once_flag first_once, third_once;
  mutable std::atomic<bool> first_built{false};  // set once `first` below is complete
  // Certifying by perturbation (Step 4e), per voxel (built on first use; reduced mode only): Γ_i = g2 + rest
  // ≥ sup over its ball of the norm of the map ỹ ↦ J, with its center part g2 ≥ ‖G_i‖₂; and ‖G̃_i‖_F of the
  // stored rows.
  mutable std::once_flag gamma_once;
  // Set once pert is complete: a cache store asks for it from its own thread.
  mutable std::atomic<bool> pert_built{false};
  mutable OctreeCertifier::PerturbationConstants pert;
  // Certifying by perturbation, the rest from a direction (Step 4e): for the direction d of the last line
  // search, ‖δ_e(Ξ d)‖_F per cage edge and per voxel r_i Σ_e Θ¹_e(B_i) ‖δ_e(Ξ d)‖ (NaN: not computed yet:
  // only voxels the Cauchy–Schwarz rest does not take over need it). Kept while d is the same, so the later
  // trials of a line search reuse it; each value depends on d and its voxel only.
  mutable std::mutex direction_mutex;
  mutable Eigen::Matrix<double, Eigen::Dynamic, 3> direction;
  mutable VecXd direction_delta, direction_rest;
  // The same rest for a group of neighbouring voxels at once (Step 4e, "Voxel groups"): the voxels of each
  // block of 2 x 2 x 2 base cells (of 8 consecutive voxels without a grid), group g holding
  // group_voxels[group_start[g] .. group_start[g + 1]); per group and edge the largest first-order factor of
  // its voxels and the largest radius, so that one row of #E floats bounds the rest of all of them. Built
  // with the first-order factors; group_rest per group for the cached direction.
  mutable std::vector<long> group_start, group_voxels;
  mutable std::vector<int> group_of;  // per voxel its group
  mutable Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> group_first;
  mutable std::vector<char> group_finite;
  mutable VecXd group_radius, group_rest;
  // The voxel lookup of the distortion probes (built on first use: every line-search trial asks it).
  mutable std::once_flag locator_once;
  mutable std::unique_ptr<VoxelLocator> locator;
  mutable std::vector<char> first_finite, third_finite;  // per voxel: no factor is +∞
  // Stored as floats rounded *up*, so that they stay upper bounds.
  mutable Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> first, third;
  // Backend kernels (nullptr: the CPU code below) and which factor matrices they hold.
  std::unique_ptr<CertifierKernels> kernels;
  mutable bool kernels_first = false, kernels_third = false;
  std::unique_ptr<EdgeJet> edge_jet;  // per-edge evaluation of octree children (edge_jet.h)
  // The guard: per voxel, its ball B(center, radius_of(i)) is clear of the cage (distance > radius, winding
  // number 1). A voxel that is not is never certified, whoever built the sampling.
  std::vector<char> clear;
};

OctreeCertifier::OctreeCertifier(const Cage& cage, const VoxelSampling& sampling, const MatXd* reduction,
                                 double max_matrix_bytes, const std::function<void(double)>& on_chunk)
    : cage_(cage), sampling_(sampling), basis_(cage), impl_(std::make_unique<Impl>()) {
  const auto t0 = Clock::now();
  init_common(reduction);
  Impl& im = *impl_;
  const long N = sampling.size(), n = basis_.size();
  const long m = reduction ? reduction->cols() : n;
  if (reduction && reduction->rows() != n)
    throw InputError("", "reduction basis has " + std::to_string(reduction->rows()) +
                             " rows, expected #V+#F = " + std::to_string(n));
  const double bytes = 9.0 * N * m * sizeof(float);
  if (reduction || bytes <= max_matrix_bytes) {
    im.mode = reduction ? Impl::Mode::kReduced : Impl::Mode::kFull;
    im.m = m;
    im.GH.resize(static_cast<size_t>(9 * N * m));
    im.scale_J.resize(N);
    im.scale_H.resize(N);
    // Per chunk of centers: the basis gradients and Hessians, one block of 8 rows per center (3 gradient
    // rows, the Hessian's xx, xy, xz, yy, yz), times Ξ (OpenBLAS), then GH's 9-row block rounded to float,
    // its zz row = −xx − yy in double (the basis is harmonic: an identity, docs/certificate.md Step 5; the
    // product is a ninth smaller). The buffers keep their memory from chunk to chunk.
    const long chunk = 1024;
    MatXdR D, R;
    for (long s = 0; s < N; s += chunk) {
      const long c = std::min(chunk, N - s);
      basis_.evaluate_rows(sampling.centers.middleRows(s, c), false, true, true, D, /*drop_zz=*/true);
      if (reduction) blas_product(D, *reduction, R);
      const MatXdR& F = reduction ? R : D;  // 8c by m
#pragma omp parallel for schedule(static)
      for (long j = 0; j < c; ++j) {
        float* blk = im.GH.data() + static_cast<size_t>((s + j) * 9 * m);
        const double* src = F.data() + static_cast<size_t>(8 * j * m);
        double sj = 0, sh = 0;
        for (long q = 0; q < 9 * m; ++q) {
          const double exact = q < 8 * m ? src[q] : -(src[q - 5 * m] + src[q - 2 * m]);  // zz = −xx − yy
          const float v = static_cast<float>(exact);
          blk[q] = v;
          (q < 3 * m ? sj : sh) += std::abs(static_cast<double>(v));
        }
        im.scale_J(s + j) = sj;
        im.scale_H(s + j) = sh;
      }
      if (on_chunk) on_chunk(static_cast<double>(s + c) / static_cast<double>(N));
    }
  }
  precompute_seconds_ = ms_since(t0) / 1000.0;
}

OctreeCertifier::OctreeCertifier(const Cage& cage, const VoxelSampling& sampling, const MatXd* reduction,
                                 ReducedDerivatives d)
    : cage_(cage), sampling_(sampling), basis_(cage), impl_(std::make_unique<Impl>()) {
  const auto t0 = Clock::now();
  if (!reduction) throw Error("OctreeCertifier: precomputed derivatives need the reduction basis");
  init_common(reduction);
  Impl& im = *impl_;
  const long N = sampling.size();
  if (d.m != reduction->cols() || d.GH.size() != static_cast<size_t>(9 * N * d.m) || d.scale_J.size() != N ||
      d.scale_H.size() != N)
    throw Error("OctreeCertifier: precomputed derivatives of another shape");
  im.mode = Impl::Mode::kReduced;
  im.m = d.m;
  im.GH = std::move(d.GH);
  im.scale_J = std::move(d.scale_J);
  im.scale_H = std::move(d.scale_H);
  precompute_seconds_ = ms_since(t0) / 1000.0;
}

void OctreeCertifier::init_common(const MatXd* reduction) {
  if (!(sampling_.side > 0)) throw InputError("", "voxel side must be > 0");
  if (sampling_.size() == 0) throw InputError("", "no voxels to certify");
  if (!sampling_.level.empty() && static_cast<long>(sampling_.level.size()) != sampling_.size())
    throw InputError("", "voxel levels: " + std::to_string(sampling_.level.size()) + " for " +
                             std::to_string(sampling_.size()) + " voxels");
  Impl& im = *impl_;
  im.clear = balls_clear_of_cage(cage_, sampling_);
  im.reduction = reduction;
  im.edge_jet = std::make_unique<EdgeJet>(cage_);
  for (const CageEdge& e : cage_.edges) {
    im.eu.push_back(cage_.V.row(e.v0));
    im.ew.push_back(cage_.V.row(e.v1));
  }
}

const OctreeCertifier::FactorMatrix* OctreeCertifier::built_factors(bool third_kind,
                                                                    const std::vector<char>** finite) const {
  const Impl& im = *impl_;
  if (third_kind ? im.third.size() == 0 : !im.first_built.load(std::memory_order_acquire)) return nullptr;
  *finite = third_kind ? &im.third_finite : &im.first_finite;
  return third_kind ? &im.third : &im.first;
}

void OctreeCertifier::adopt_factors(bool third_kind, FactorMatrix factors, std::vector<char> finite) {
  Impl& im = *impl_;
  if (factors.rows() != sampling_.size() || factors.cols() != cage_.num_edges() ||
      finite.size() != static_cast<size_t>(sampling_.size()))
    throw Error(std::string("OctreeCertifier: ") + (third_kind ? "third" : "first") +
                "-order factors of another shape");
  if (third_kind) {
    std::call_once(im.third_once, [&] {
      im.third = std::move(factors);
      im.third_finite = std::move(finite);
    });
    return;
  }
  std::call_once(im.first_once, [&] {
    im.first = std::move(factors);
    im.first_finite = std::move(finite);
    build_groups();
    im.first_built.store(true, std::memory_order_release);
  });
}

void OctreeCertifier::build_groups() const {
  const Impl& im = *impl_;
  const long N = sampling_.size(), E = cage_.num_edges();
  // The voxels in order of their block's key (then their own index): a block of base cells, or 8 consecutive
  // voxels without a grid.
  std::vector<long> key(N);
  const MatX3i& g = sampling_.grid_index;
  const bool grid = g.rows() == N;
  // Cells per group along each axis: blocks of 3 were no faster, of 4 slower (looser rows fail more voxels).
  constexpr long kB = 2;
  long kmax[3] = {0, 0, 0};
  if (grid)
    for (long i = 0; i < N; ++i)
      for (int a = 0; a < 3; ++a) kmax[a] = std::max<long>(kmax[a], g(i, a) / kB + 1);
  for (long i = 0; i < N; ++i)
    key[i] = grid ? (g(i, 2) / kB * kmax[1] + g(i, 1) / kB) * kmax[0] + g(i, 0) / kB : i / (kB * kB * kB);
  im.group_voxels.resize(N);
  std::iota(im.group_voxels.begin(), im.group_voxels.end(), 0L);
  std::stable_sort(im.group_voxels.begin(), im.group_voxels.end(),
                   [&](long a, long b) { return key[a] < key[b]; });
  im.group_start.assign(1, 0);
  for (long k = 1; k <= N; ++k)
    if (k == N || key[im.group_voxels[k]] != key[im.group_voxels[k - 1]]) im.group_start.push_back(k);
  const long G = static_cast<long>(im.group_start.size()) - 1;
  im.group_of.resize(N);
  for (long q = 0; q < G; ++q)
    for (long k = im.group_start[q]; k < im.group_start[q + 1]; ++k)
      im.group_of[im.group_voxels[k]] = static_cast<int>(q);
  im.group_first.resize(G, E);
  im.group_finite.assign(G, 1);
  im.group_radius.resize(G);
  // Maxima of floats rounded up: exact, so each row bounds every member's factors.
#pragma omp parallel for schedule(static)
  for (long q = 0; q < G; ++q) {
    float* row = im.group_first.row(q).data();
    double r = 0;
    for (long k = im.group_start[q]; k < im.group_start[q + 1]; ++k) {
      const long i = im.group_voxels[k];
      const float* f = im.first.row(i).data();
      if (k == im.group_start[q])
        std::copy(f, f + E, row);
      else
        for (long e = 0; e < E; ++e) row[e] = std::max(row[e], f[e]);
      im.group_finite[q] = im.group_finite[q] && im.first_finite[i];
      r = std::max(r, sampling_.radius_of(static_cast<int>(i)));
    }
    im.group_radius(q) = r;
  }
}

OctreeCertifier::VoxelGroups OctreeCertifier::voxel_groups() const {
  const Impl& im = *impl_;
  if (!im.first_built.load(std::memory_order_acquire)) return {};
  return {im.group_start, im.group_voxels, im.group_first, im.group_radius, im.group_finite};
}

OctreeCertifier::ReducedDerivativesRef OctreeCertifier::reduced_derivatives() const {
  ReducedDerivativesRef d;
  const Impl& im = *impl_;
  if (im.mode != Impl::Mode::kReduced) return d;
  d.GH = &im.GH;
  d.m = im.m;
  d.scale_J = &im.scale_J;
  d.scale_H = &im.scale_H;
  return d;
}

bool OctreeCertifier::direction_rest_pays() const {
  const Impl& im = *impl_;
  return im.mode == Impl::Mode::kReduced && cage_.num_edges() <= 3 * im.m;
}

OctreeCertifier::~OctreeCertifier() = default;

void OctreeCertifier::set_backend(const ComputeBackend& backend) {
  Impl& im = *impl_;
  CertifierData d;
  d.cage = &cage_;
  d.voxels = sampling_.size();
  d.centers = &sampling_.centers;
  d.m = im.mode == Impl::Mode::kOnTheFly ? 0 : im.m;
  d.GH = im.GH.empty() ? nullptr : im.GH.data();
  d.edge_u = im.eu;
  d.edge_w = im.ew;
  im.kernels = backend.certifier_kernels(d);
  im.kernels_first = im.kernels_third = false;
}

VecXd OctreeCertifier::edge_delta_norms(const MatX3d& y) const {
  return delta_norms(basis_.face_matrices(y));
}

VecXd OctreeCertifier::delta_norms(const HarmonicBasis::FaceMatrices& fm) const {
  VecXd out(cage_.num_edges());
  for (int e = 0; e < cage_.num_edges(); ++e)
    out(e) = (fm.A[cage_.edges[e].f0] - fm.A[cage_.edges[e].f1]).norm();
  return out;
}

std::string Certificate::distortion_reason() const {
  if (failing.empty()) return reason;
  std::string r = targets().reason(distortion_failed_on, failing.front().center);
  if (distortion_budget > 0)
    r += " (refinement budget of " + std::to_string(distortion_budget) + " nodes used up)";
  return r;
}

Certificate OctreeCertifier::certify(const MatX3d& y, const CertifyParams& params) const {
  if (y.rows() != basis_.size())
    throw InputError("", "coefficients have " + std::to_string(y.rows()) +
                             " rows, expected #V+#F = " + std::to_string(basis_.size()));
  if (!y.allFinite()) throw InputError("", "coefficients contain NaN or Inf");
  return run(y, nullptr, 0, params);
}

MatX3d OctreeCertifier::expand_reduced(const Eigen::Matrix<double, Eigen::Dynamic, 3>& yr,
                                       const char* caller) const {
  if (!impl_->reduction) throw Error(std::string(caller) + " needs a certifier built with a reduction basis");
  if (yr.rows() != impl_->reduction->cols())
    throw InputError("", "reduced coefficients have " + std::to_string(yr.rows()) + " rows, expected " +
                             std::to_string(impl_->reduction->cols()));
  if (!yr.allFinite()) throw InputError("", "reduced coefficients contain NaN or Inf");
  return (*impl_->reduction) * yr;
}

Certificate OctreeCertifier::certify_reduced(const Eigen::Matrix<double, Eigen::Dynamic, 3>& yr,
                                             const CertifyParams& params) const {
  const MatX3d y = expand_reduced(yr, "certify_reduced");
  return run(y, yr.data(), yr.rows(), params);
}

// The factor matrix of one bound (third order, or first order), built on first use (it depends only on the
// cage and the voxels).
const OctreeCertifier::FactorMatrix& OctreeCertifier::factor_matrix(bool third_kind) const {
  const Impl& im = *impl_;
  const long N = sampling_.size(), E = cage_.num_edges();
  // One row per voxel, vectorized over the edges (lipschitz_bound.h, factor_row).
  auto build = [&](FactorMatrix& mat, std::vector<char>& finite, bool third) {
    const EdgeArrays edges(im.eu, im.ew);
    mat.resize(N, E);
    finite.assign(N, 1);
#pragma omp parallel for schedule(static)
    for (long i = 0; i < N; ++i)
      finite[i] = factor_row(edges, third ? EdgeFactor::kThirdOrder : EdgeFactor::kFirstOrder,
                             sampling_.centers.row(i).transpose(), sampling_.radius_of(static_cast<int>(i)),
                             mat.row(i).data());
  };
  if (third_kind) {
    std::call_once(im.third_once, [&] { build(im.third, im.third_finite, true); });
    return im.third;
  }
  std::call_once(im.first_once, [&] {
    build(im.first, im.first_finite, false);
    build_groups();
    im.first_built.store(true, std::memory_order_release);
  });
  return im.first;
}

// Γ_i = ‖G(c)‖₂ + r (‖H(c)‖_F + ½ r Σ_e W_e Θ_e(B_i)), the reduced basis' gradients G (3 by s) and
// Hessians H (27 by s) at the center from the stored rows (each within 2⁻²⁴ of its value: × (1 + 2⁻²³)),
// W_e = sqrt(Σ_k ‖δ_e(ψ_k)‖²) over the reduced basis functions ψ_k (Step 2's δ of a scalar function, a
// 3-vector), Θ the third-order factors (Step 3). Then ‖J(ỹ) − J(ỹ₀)‖_F ≤ Γ_i ‖ỹ − ỹ₀‖_F on the ball (Step
// 4e).
const OctreeCertifier::PerturbationConstants& OctreeCertifier::perturbation_constants() const {
  const Impl& im = *impl_;
  if (im.mode != Impl::Mode::kReduced || !im.reduction)
    throw Error("OctreeCertifier: perturbation constants need a certifier with a reduction");
  const long N = sampling_.size(), E = cage_.num_edges();
  std::call_once(im.gamma_once, [&] {
    const MatXd& xi = *im.reduction;
    const long s = xi.cols();
    VecXd W2 = VecXd::Zero(E);
    for (long k0 = 0; k0 < s; k0 += 3) {
      MatX3d Y = MatX3d::Zero(xi.rows(), 3);
      for (int a = 0; a < 3 && k0 + a < s; ++a) Y.col(a) = xi.col(k0 + a);
      const HarmonicBasis::FaceMatrices f = basis_.face_matrices(Y);
      for (long e = 0; e < E; ++e) {
        const CageEdge& ce = cage_.edges[e];
        W2(e) += (f.A[ce.f0] - f.A[ce.f1]).squaredNorm();  // the 3 rows: 3 basis functions
      }
    }
    const VecXd W = W2.cwiseSqrt() * (1 + 1e-12);
    const auto& factors = factor_matrix(true);
    const long m = im.m;
    constexpr double kStored = 1 + 0x1p-23;
    // The sums below run in SIMD lanes, in the compiler's order; float × float products are exact in
    // double, so only the sums round: ≤ 3 m u relative for the Gram row sums (each entry within m u of
    // Σ|products| ≤ √(G_aa G_bb) ≤ gj), ≤ (m + 6) u for the non-negative Hessian and diagonal sums,
    // ≤ (E + 1) u for Σ_e W_e Θ_e (each product rounded once). kSums covers all of them for any s and cage.
    const double kSums = 1 + 1e-12 + 3.0 * static_cast<double>(m + E + 16) * 0x1p-53;
    PerturbationConstants out;
    out.g2.resize(N), out.rest.resize(N), out.gF.resize(N);
#pragma omp parallel for schedule(static)
    for (long i = 0; i < N; ++i) {
      const float* blk = im.GH.data() + static_cast<size_t>(i * 9 * m);
      // ‖G‖₂² = λ_max(G Gᵀ) ≤ the largest absolute row sum of the 3×3 Gram matrix (Gershgorin), up to √3
      // below ‖G‖_F² where the three gradient rows are nearly orthogonal and of equal length.
      double gram[3][3] = {};
      for (int a = 0; a < 3; ++a)
        for (int b = a; b < 3; ++b) gram[a][b] = gram[b][a] = float_dot(blk + a * m, blk + b * m, m);
      double gj = 0;
      for (int a = 0; a < 3; ++a)
        gj = std::max(gj, std::abs(gram[a][0]) + std::abs(gram[a][1]) + std::abs(gram[a][2]));
      gj *= kSums;
      double gh = 0;
      for (int row = 3; row < 9; ++row) {  // 3 xx, 4 xy, 5 xz, 6 yy, 7 yz, 8 zz: off-diagonals twice
        const float* h = blk + row * m;
        gh += (row == 4 || row == 5 || row == 7 ? 2 : 1) * float_dot(h, h, m);
      }
      const double t = im.third_finite[i] ? weighted_float_sum(W.data(), factors.row(i).data(), E) : kInf;
      const double r = sampling_.radius_of(static_cast<int>(i));
      out.g2(i) = std::sqrt(gj) * kStored;
      out.rest(i) = r * (std::sqrt(gh) * kStored + 0.5 * r * t) * kSums;
      out.gF(i) = std::sqrt(gram[0][0] + gram[1][1] + gram[2][2]) * kSums;
    }
    im.pert = std::move(out);
    im.pert_built.store(true, std::memory_order_release);
  });
  return im.pert;
}

void OctreeCertifier::adopt_perturbation_constants(PerturbationConstants constants) {
  Impl& im = *impl_;
  const long N = sampling_.size();
  if (constants.g2.size() != N || constants.rest.size() != N || constants.gF.size() != N)
    throw Error("OctreeCertifier: perturbation constants of another shape");
  std::call_once(im.gamma_once, [&] {
    im.pert = std::move(constants);
    im.pert_built.store(true, std::memory_order_release);
  });
}

const OctreeCertifier::PerturbationConstants* OctreeCertifier::perturbation_constants_if_built() const {
  return impl_->pert_built.load(std::memory_order_acquire) ? &impl_->pert : nullptr;
}

// One certification, as the list of its stages (run() below). Every decision is taken here, on the host, in
// base-voxel order, so the verdict depends neither on the thread schedule nor on the backend.
struct OctreeCertifier::Run {
  // A node of the refinement octree below a failing base voxel.
  struct Node {
    Vec3 c;
    double side;
    int depth;
    double bound;        // third, combined: Σ δ Θ over the node's ball; first: L over the node's ball
    double bound_first;  // combined: Σ δ Γ over the node's ball (first-order L)
    long fi;             // index into failing_base
    int first_child;     // index of the first of its 8 children in `tree` (−1: a leaf)
    CertLeaf leaf;
    int far = -1;  // far-field refinement: index into `far` of its parent's FarField (−1: evaluated exactly)
  };
  // Far-field refinement (RefinementEval::kFarField, docs/certificate.md Step 4d): what the 8 children of a
  // subdivided node P share. With N = the faces near P and F_far = J − F_N (the other faces' part), for q in
  // B(c, rad): F_far(q) = J_far + H_far[q − c] + R, ‖R‖_F ≤ ½|q − c|² T.
  struct FarField {
    Vec3 c = Vec3::Zero();
    std::vector<int> near;  // N, ascending
    EdgeJet::Patch patch;   // the faces of N
    Mat3 J = Mat3::Zero();  // J̃_far(c) = J̃(c) − J_N(c), |J_far(c) − J̃_far(c)|₂ ≤ eps_J
    std::array<Mat3, 3> H{Mat3::Zero(), Mat3::Zero(), Mat3::Zero()};  // ‖H_far(c) − H̃_far(c)‖_F ≤ eps_H
    double eps_J = 0, eps_H = 0;
    double T = kInf;                  // ≥ sup over B(c, rad) of ‖D³F_far‖_F (81 entries)
    double scale_J = 0, scale_H = 0;  // rounding magnitudes of J̃_far, H̃_far
    bool ok = false;                  // false: children are evaluated exactly
  };
  // A node's J̃ and H̃ (needed when it is subdivided: its children's FarField).
  struct Jet {
    Mat3 J = Mat3::Zero();
    std::array<Mat3, 3> H{Mat3::Zero(), Mat3::Zero(), Mat3::Zero()};
  };
  // The refinement of one failing base voxel.
  struct VoxelState {
    bool ok = true, definite_fail = false;
    bool failed_here = false;  // its own proof failed (Certificate::failed_voxels)
    long refined = 1, evaluated = 0;
    int depth_used = 0;
    double min_sigma = kInf;
    int first_child = -1;
  };

  const OctreeCertifier& oc;
  const Impl& im;
  const MatX3d& y;
  const double* yr_ptr;  // reduced coefficients (s by 3, column-major) or nullptr
  long yr_rows;
  const CertifyParams& p;
  const DistortionTargets targets;  // p's (Run keeps the value: the stages ask it per leaf)
  const long N, E;
  const double side;      // base voxel side (a voxel's own: side_of(i))
  const bool third;       // ‖H(c)‖ and Σ δ Θ needed (third and combined)
  const bool combined;    // per leaf min(first-order loss, Taylor form with ‖H(c)‖_op)
  const bool spectral;    // combined, and the Taylor σ3 lower bound as a third candidate (Step 3c)
  const bool use_stored;  // J and H at the base centers from the stored basis derivatives
  const bool far_mode;    // far-field refinement (third-order bound; on the host with every backend)
  // Step 3d: the Taylor bounds of σ1, σ3 and σ1/σ3 (taylor_singular_bounds) at every node evaluated exactly
  // on the host and at the base voxels whose Lipschitz bounds do not prove a target, with a third-order
  // bound (its T bounds the Taylor remainder) and distortion targets (without targets the certificates stay
  // those of the Lipschitz bounds alone).
  const bool taylor;
  // Step 4f: base voxels the third-order bound leaves unproven try the spectral bound's loss before they are
  // refined (CertifyParams::base_spectral_fallback, where it applies: stored derivatives, no target).
  const bool fallback;
  const HarmonicBasis::FaceMatrices fm;
  Certificate cert;
  // Base voxels.
  VecXd scaleJ, scaleH, hnorm, sigma3, T, delta;
  VecXd sigma1;   // σ1 at the base centers (NaN: not computed, e.g. on a backend's base stage)
  VecXd hop, T1;  // combined: operator-norm bound of H(c) and the first-order Σ δ Γ
  VecXd lb2;      // spectral: taylor_sigma3_lower_bound at the base centers (−∞: none)
  // taylor: at the base centers evaluated on the fly (not valid: none); from the stored derivatives only the
  // Hessians are kept (Hbase), and the bounds are formed where the Lipschitz bounds do not prove a target.
  std::vector<TaylorSingularBounds> tsb;
  std::vector<std::array<Mat3, 3>> Hbase;
  std::vector<Mat3> Jc;
  std::vector<char> sign_unresolved;  // per base voxel: det J's sign at the center not resolved
  std::vector<double> device_Y;       // coefficients for the backend's base stage (empty: CPU)
  std::vector<CertLeaf> base;
  std::vector<long> failing_base;
  // Certifying by perturbation: per base voxel 1 when certified from the previous map, and that bound.
  std::vector<char> perturbed;
  VecXd perturbed_lower, perturbed_upper;
  bool evaluated(long i) const { return perturbed.empty() || !perturbed[i]; }
  // The evaluated base voxels in order (all of them unless the perturbation stage took some over). The
  // per-voxel stages loop over this list: voxels taken over cluster in space, so a static split of 0..N−1
  // left one thread most of the work.
  std::vector<long> eval_list;
  void list_evaluated() {
    eval_list.clear();
    eval_list.reserve(N);
    for (long i = 0; i < N; ++i)
      if (evaluated(i)) eval_list.push_back(i);
  }
  // Refinement.
  std::vector<VoxelState> vs;
  std::vector<Node> tree;
  std::vector<int> frontier;
  long budget_used = 0;
  bool abort = false, budget_hit = false;

  Run(const OctreeCertifier& o, const MatX3d& y_, const double* yr, long yr_n, const CertifyParams& params)
      : oc(o),
        im(*o.impl_),
        y(y_),
        yr_ptr(yr),
        yr_rows(yr_n),
        p(params),
        targets(params.targets()),
        N(o.sampling_.size()),
        E(o.cage_.num_edges()),
        side(o.sampling_.side),
        third(params.bound != LipschitzBound::kFirstOrder),
        combined(params.bound == LipschitzBound::kCombined || params.bound == LipschitzBound::kSpectral),
        spectral(params.bound == LipschitzBound::kSpectral),
        use_stored(im.mode == Impl::Mode::kFull || (im.mode == Impl::Mode::kReduced && yr)),
        far_mode(params.refinement == RefinementEval::kFarField && third && !combined),
        taylor(third && params.taylor_bounds && params.targets().any()),
        fallback(params.base_spectral_fallback && third && !combined && use_stored && !taylor),
        fm(o.basis_.face_matrices(y_)) {
    cert.bound = p.bound;
    cert.voxel_side = side;
    cert.voxels = static_cast<int>(N);
  }

  // Exact J, ‖H‖ and rounding scales at any point, from the full coefficients through the differential
  // representation (one pass over the faces per point; see HarmonicBasis::differential_jet).
  void eval_point(const Vec3& c, Mat3& J, double& hn, double& sJ, double& sH, double* hn_op = nullptr,
                  double rad = 0, double* lb = nullptr, TaylorSingularBounds* tb = nullptr) const {
    const MapJet jet = oc.basis_.differential_jet(fm, c, third ? 2 : 1, &sJ, &sH);
    J = jet.J;
    hn = third ? jet.hessian_norm() : 0.0;
    if (hn_op) *hn_op = combined ? hessian_operator_norm(jet.H) : 0.0;
    if (lb) *lb = spectral ? taylor_sigma3_lower_bound(jet.J, jet.H, rad) : -kInf;
    if (tb && taylor) *tb = taylor_singular_bounds(jet.J, jet.H, rad);
  }
  // Spectral: the smaller of ‖H(c)‖_op and the Taylor σ3 bound's first-order loss (σ3(c) − ℓ)/r, so that
  // lipschitz() gives min(first order, that + ½ r T3) (Step 3c).
  // Only at a center with σ3 > 0 (resolved): ℓ then bounds the same positive σ3, and the loss is never
  // negative (ℓ ≤ σ3(c) up to rounding).
  static double taylor_part(double hn_op, double s3, double lb, double rad) {
    if (!(rad > 0) || !(s3 > 0) || !(lb > -kInf)) return hn_op;
    return std::min(hn_op, std::max(0.0, (s3 - lb) / rad));
  }
  // The L of condition (6), so that the loss over the leaf is rad·L (docs/certificate.md, Steps 1-3b):
  //   first: t1;  third: ‖H(c)‖_F + rad·t3;  combined: min(t1, ‖H(c)‖_op + ½ rad·t3) — the Taylor form
  //   |σ3(q) − σ3(c)| ≤ |q−c| ‖H(c)‖_op + ½ |q−c|² t3 ≤ rad (‖H(c)‖_op + ½ rad t3) for |q − c| ≤ rad.
  double lipschitz(double hn, double hn_op, double t1, double t3, double rad) const {
    if (combined) return std::min(t1, hn_op + 0.5 * rad * t3);
    return third ? hn + rad * t3 : t1;
  }
  // Allowance for rounding: kRoundingRel covers the double-precision evaluation and summation (relative to
  // the magnitudes summed); `storage` covers float storage of the basis derivatives: each stored value is
  // within 2⁻²⁴ of the exact one, so Σ|ΔJ_ab| ≤ 2⁻²⁴·3·cmax·Σ|G| and ‖ΔH‖_F ≤ 2⁻²⁴·6·cmax·Σ|H|, and by
  // Weyl |Δσ3| ≤ ‖ΔJ‖₂ ≤ Σ|ΔJ_ab|, |Δ‖H‖| ≤ ‖ΔH‖_F.
  static double tolerance(double sJ, double sH, double s3, double L, double rad, double storage) {
    return kRoundingRel * (sJ + rad * sH + std::abs(s3) + rad * L) + storage * (sJ + rad * sH);
  }
  // Bounded distortion (docs/certificate.md, "Bounded distortion"). On the leaf's ball σ1(q) ≤ σ1(J̃(c)) +
  // eps_J + rad·L1 + τ1: σ1 is 1-Lipschitz in the spectral norm (Weyl), |σ1(J(c)) − σ1(J̃(c))| ≤ eps_J, and
  // rad·L1 bounds ‖J(q) − J(c)‖ over the ball (every bound's L except the spectral one's Taylor term, which
  // is specific to σ3); τ1 is the allowance τ with σ1 and L1 in place of σ3 and L. The factor 1 + 1e-15
  // covers the rounding of the four additions (each ≤ u relative, all terms ≥ 0). σ1 NaN (not computed):
  // no bound (+∞).
  // Where the leaf's center was evaluated exactly (or from the stored derivatives), `tb` holds its Taylor
  // bounds (Step 3d) and `T3` its third-order sum: of each pair of bounds (σ1, σ3, σ1/σ3) the better one is
  // kept, as both hold on the whole ball. Only on a certified leaf for σ3 and σ1/σ3: which leaves are
  // certified stays the Lipschitz bound's decision, the Taylor bound only tightens their margins.
  void set_distortion(CertLeaf& l, double s1, double eps_J, double L1, double rad, double sJ, double sH,
                      double storage, const TaylorSingularBounds* tb = nullptr, double T3 = kInf) const {
    l.sigma1 = s1;
    const double up = (s1 + eps_J + rad * L1 + tolerance(sJ, sH, s1, L1, rad, storage)) * (1 + 1e-15);
    l.sigma1_upper = std::isfinite(up) && s1 >= 0 ? up : kInf;
    if (tb && tb->valid && eps_J == 0) {
      const double rho = taylor_remainder(rad, T3, sJ, sH, storage);
      l.sigma1_upper = std::min(l.sigma1_upper, taylor_sigma1_upper_bound(*tb, rad, rho));
      if (l.margin > 0) l.margin = std::max(l.margin, taylor_sigma3_lower_bound(*tb, rad, rho));
      l.distortion_upper = std::min(distortion_of(l.sigma1_upper, l.margin),
                                    l.margin > 0 ? taylor_distortion_bound(*tb, rad, rho) : kInf);
      return;
    }
    l.distortion_upper = distortion_of(l.sigma1_upper, l.margin);
  }
  // Step 3d's ρ ≥ ‖J(q) − J̃ − H̃[q − c]‖₂ on the ball: the Taylor remainder ½ r² T3 (Step 3b (c)), the
  // double-precision evaluation of J̃ and H̃ (kRoundingRel of their scales) and the float storage of the
  // basis derivatives (`storage`, Step 5).
  static double taylor_remainder(double rad, double T3, double sJ, double sH, double storage) {
    return (0.5 * rad * rad * T3 + (kRoundingRel + storage) * (sJ + rad * sH)) * (1 + 1e-12);
  }
  // The targets asked for, as the certificate reports them.
  void set_targets(Certificate& c) const {
    c.max_distortion = targets.max_distortion;
    c.max_sigma1 = targets.max_sigma1;
    c.min_sigma3 = targets.min_sigma3;
  }
  // The leaf's bounds against the targets (DistortionTargets::unproven and excess).
  DistortionTarget unproven(const CertLeaf& l) const {
    return targets.unproven(l.sigma1_upper, l.margin, l.distortion_upper);
  }
  double excess(const CertLeaf& l) const {
    return targets.excess(l.sigma1_upper, l.margin, l.distortion_upper);
  }
  // An upper bound of σ1/σ3 from an upper bound of σ1 and a positive lower bound of σ3 (the quotient rounded
  // up by 1e-15 relative); +∞ without a positive lower bound.
  static double distortion_of(double upper, double lower) {
    if (!(lower > 0) || !(upper >= 0)) return kInf;
    const double k = upper / lower * (1 + 1e-15);
    return std::isfinite(k) ? k : kInf;
  }

  // The signed singular values at a probe and the target they prove violated there (kNone: none proven).
  struct ProbeValue {
    Vec3 sv = Vec3::Zero();
    DistortionTarget which = DistortionTarget::kNone;
  };

  // --- −1. Probing the distortion targets (CertifyParams::distortion_probes). At a probe q inside the
  // voxels, σ_i(J(q)) lies within τ_i (the rounding allowance of the double-precision evaluation, as for a
  // center) of the computed σ̃_i; (σ̃1 − τ1)/(σ̃3 + τ3) > K then proves σ1/σ3 > K at q (σ̃1 − τ1 > S proves
  // σ1 > S, σ̃3 + τ3 < s proves σ3 < s), and the leaf holding q can never prove the target (its bounds cover
  // a ball containing q). Returns true with `out` filled (not certified, the distortion reason at q) when a
  // probe fails.
  // With `search`, the search near the probes follows when none proves a violation (−1b).
  bool distortion_probe(Certificate& out, bool search = true) const {
    if (!p.stop_on_failure || !targets.any() || p.distortion_probes.empty()) return false;
    const std::vector<long> voxel = probe_voxels();
    // The first probe (the trial's own worst sample) proves most refusals alone; the others are evaluated
    // together over the threads only when it does not. The verdict is that of the first probe in order
    // that proves a violation, as if they were evaluated one by one.
    const long n = static_cast<long>(voxel.size());
    std::vector<ProbeValue> v(voxel.size());
    v[0] = probe_value(p.distortion_probes[0], voxel[0]);
    if (v[0].which == DistortionTarget::kNone && n > 1) {
#pragma omp parallel for schedule(dynamic, 1)
      for (long k = 1; k < n; ++k) v[k] = probe_value(p.distortion_probes[k], voxel[k]);
    }
    for (long k = 0; k < n; ++k)
      if (v[k].which != DistortionTarget::kNone) {
        refuse_at(out, p.distortion_probes[k], voxel[k], v[k]);
        return true;
      }
    return search && violation_search(out, v, voxel);
  }
  // The refusal of a trial by a violation proven at q (in base voxel `voxel`): not certified, the
  // distortion reason at q, q as the failing leaf (the next trials probe it first).
  void refuse_at(Certificate& out, const Vec3& q, long voxel, const ProbeValue& v) const {
    CertLeaf l;
    l.center = q;
    l.sigma3 = v.sv(2);
    l.sigma1 = v.sv(0);
    l.base = static_cast<int>(voxel);
    l.certified = true;  // σ3 is not in question here; the distortion is
    out.failing.push_back(l);
    out.failed_voxels.push_back(voxel);
    out.certified = false;
    out.distortion_failed = true;
    out.distortion_failed_on = v.which;
    set_targets(out);
    out.voxel_side = side;
    out.voxels = static_cast<int>(N);
    out.min_sigma3_center = v.sv(2);
    out.reason = targets.reason(v.which, q);
  }
  // --- −1b. When no probe proves a violation but one comes close (computed excess ≥ kSearchFrom): a short
  // pattern search for a point that does, from the probe of largest computed excess, along the axes with
  // steps from a quarter of its voxel's side down to 1/64 (at most kSearchEvaluations points). The points
  // are evaluated and judged exactly as probes, so a refusal here is a proven violation at a point of the
  // domain, the verdict every certificate reaches (docs/certificate.md, "Probes"); the search only saves
  // the evaluation of the voxels when the full certificate would fail on a leaf near the probe. Finding
  // nothing decides nothing.
  static constexpr double kSearchFrom = 0.98;
  static constexpr int kSearchEvaluations = 60;
  bool violation_search(Certificate& out, const std::vector<ProbeValue>& v,
                        const std::vector<long>& voxel) const {
    auto rank = [&](const ProbeValue& pv) {  // the computed excess; folds and failed evaluations rank 0
      return pv.sv(2) > 0 ? targets.excess(pv.sv(0), pv.sv(2), pv.sv(0) / pv.sv(2)) : 0.0;
    };
    long best = -1;
    double ex = kSearchFrom;
    for (size_t k = 0; k < voxel.size(); ++k)
      if (voxel[k] >= 0 && rank(v[k]) >= ex) best = static_cast<long>(k), ex = rank(v[k]);
    if (best < 0) return false;
    Vec3 x = p.distortion_probes[best];
    const double side0 = oc.sampling_.side_of(static_cast<int>(voxel[best]));
    MatX3d Q(6, 3);
    std::vector<ProbeValue> pv(6);
    int evaluations = 0;
    for (double h = side0 / 4; h >= side0 / 64;) {
      for (int j = 0; j < 6; ++j) {
        Vec3 q = x;
        q(j / 2) += j % 2 ? -h : h;
        Q.row(j) = q.transpose();
      }
      const VecXi vq = locator().find(Q);
#pragma omp parallel for schedule(static, 1)
      for (int j = 0; j < 6; ++j) pv[j] = probe_value(Q.row(j).transpose(), vq(j));
      int move = -1;
      for (int j = 0; j < 6; ++j) {
        if (pv[j].which != DistortionTarget::kNone) {
          refuse_at(out, Q.row(j).transpose(), vq(j), pv[j]);
          return true;
        }
        if (vq(j) >= 0 && rank(pv[j]) > ex) move = j, ex = rank(pv[j]);
      }
      if ((evaluations += 6) >= kSearchEvaluations) break;
      if (move >= 0)
        x = Q.row(move).transpose();
      else
        h /= 2;
    }
    return false;
  }
  // The ProbeValue at q (in base voxel `voxel`, −1: outside the domain: none). Only J is needed, so the jet
  // is of order 1 (J and its rounding scale are the same as at order 2: the Hessian terms are accumulated
  // apart).
  ProbeValue probe_value(const Vec3& q, long voxel) const {
    ProbeValue r;
    if (voxel < 0) return r;
    double sJ = 0;
    const Mat3 J = oc.basis_.differential_jet(fm, q, 1, &sJ).J;
    bool resolved = true;
    r.sv = signed_singular_values(J, &resolved);
    const double s1 = r.sv(0) - tolerance(sJ, 0, r.sv(0), 0, 0, 0);
    const double s3 = r.sv(2) + tolerance(sJ, 0, r.sv(2), 0, 0, 0);
    r.which = resolved ? targets.violated(s1, s3, 1e-12) : DistortionTarget::kNone;
    // σ3 below s where it may be ≤ 0: a fold, not a distortion; the full certificate names it.
    if (r.which == DistortionTarget::kSigma3 && !(r.sv(2) - tolerance(sJ, 0, r.sv(2), 0, 0, 0) > 0))
      r.which = DistortionTarget::kNone;
    return r;
  }

  // The base voxel holding each distortion probe (−1: none).
  std::vector<long> probe_voxels() const {
    MatX3d Q(static_cast<Eigen::Index>(p.distortion_probes.size()), 3);
    for (size_t k = 0; k < p.distortion_probes.size(); ++k)
      Q.row(static_cast<Eigen::Index>(k)) = p.distortion_probes[k].transpose();
    const VecXi v = locator().find(Q);
    return std::vector<long>(v.data(), v.data() + v.size());
  }
  // The voxel lookup of the probes and the search, built once per certifier.
  const VoxelLocator& locator() const {
    std::call_once(im.locator_once, [&] { im.locator = std::make_unique<VoxelLocator>(oc.sampling_); });
    return *im.locator;
  }

  // --- 0. Certifying by perturbation (Step 4e): base voxels whose bound at the previous certified map ỹ₀
  // exceeds Γ_i ‖ỹ − ỹ₀‖_F are certified without evaluation. Reduced mode on the CPU only.
  void perturbation() {
    if (!p.previous_y || !p.previous_lower || im.mode != Impl::Mode::kReduced || !yr_ptr || im.kernels)
      return;
    const auto& y0 = *p.previous_y;
    const auto& lower = *p.previous_lower;
    if (y0.rows() != yr_rows || static_cast<long>(lower.size()) != N) return;
    double d2 = 0;
    for (int a = 0; a < 3; ++a)
      for (long k = 0; k < yr_rows; ++k) {
        const double d = yr_ptr[a * yr_rows + k] - y0(k, a);
        d2 += d * d;
      }
    const double dn = std::sqrt(d2);
    const PerturbationConstants& pc = oc.perturbation_constants();
    const double rho = direction_residual(y0);  // ≥ ‖ỹ − ỹ₀ − t d‖_F; < 0: no usable direction
    const MatS3* D = rho >= 0 ? p.direction_jacobians : nullptr;
    const double t = p.direction_step, kDir = 0x1p-30 * t * p.direction_scale + 0x1p-23 * dn;
    perturbed.assign(N, 0);
    perturbed_lower.setConstant(N, -kInf);
    perturbed_upper.setConstant(N, kInf);
    const std::vector<double>* upper =
        p.previous_upper && static_cast<long>(p.previous_upper->size()) == N ? p.previous_upper : nullptr;
    // The rest from the direction (below), for the voxels the Cauchy–Schwarz rest leaves in question. The
    // lock is held for the whole stage: the cache is the certifier's, and a concurrent certification with
    // another direction must not replace it meanwhile.
    std::unique_lock<std::mutex> direction_lock;
    const bool along = D && prepare_direction_rest(direction_lock);
    const double floor = std::max(0.0, p.perturbation_floor);
    // Dynamic chunks: the voxels that need the rest from the direction cluster in space.
#pragma omp parallel for schedule(dynamic, 256)
    for (long i = 0; i < N; ++i) {
      if (!im.clear[i]) continue;
      double center = pc.g2(i) * dn;
      if (D) {
        // ‖ΔJ(c_i)‖₂ ≤ t ‖D_i‖₂ + t ‖G̃_i d − D_i‖ + ‖G̃_i‖₂ ‖ρ‖ + ‖(G_i − G̃_i) δ‖ (Step 4e).
        const double dj = t * spectral_bound(D->middleRows(3 * i, 3)) + pc.g2(i) * rho + pc.gF(i) * kDir;
        center = std::min(center, dj);
      }
      // The factor 1 + 1e-9 covers the rounding of dn, Γ_i, ‖D_i‖ and these products (each ≤ ~1e-13
      // relative).
      if (take_over(i, (center + pc.rest(i) * dn) * (1 + 1e-9), lower, upper)) continue;
      // With ỹ − ỹ₀ = t d + ρ: sup_q ‖J(δ)(q) − J(δ)(c)‖ ≤ t R_i(d) + rest_i ‖ρ‖ (Step 4e, "the rest from a
      // direction"; R_i's rounding: the certificate's own relative allowance, 10⁻⁹). Not computed where even
      // ‖ρ‖'s share leaves no bound.
      if (!along || lower[i] - (center + pc.rest(i) * rho) * (1 + 1e-9) <= floor) continue;
      // The group's rest first (R_g(d) ≥ R_i(d): one row for all its voxels) where it leaves the voxel room
      // for a change as large in the next certificate, then the voxel's own.
      const double change_g =
          (center + t * im.group_rest(im.group_of[i]) * (1 + 1e-9) + pc.rest(i) * rho) * (1 + 1e-9);
      if (lower[i] - 2 * change_g > floor && take_over(i, change_g, lower, upper)) continue;
      const double rest = t * direction_rest(i) * (1 + 1e-9) + pc.rest(i) * rho;
      take_over(i, (center + rest) * (1 + 1e-9), lower, upper);
    }
  }
  // Takes base voxel i over when its bound at the previous map minus `change` (≥ sup over the voxel of
  // ‖J(ỹ) − J(ỹ₀)‖₂) stays above 0 and the floor and proves the distortion targets.
  bool take_over(long i, double change, const std::vector<double>& lower, const std::vector<double>* upper) {
    const double lb = lower[i] - change;
    if (!(lb > 0 && lb > p.perturbation_floor)) return false;
    // σ1 moves by at most the same ‖ΔJ‖₂ (Weyl), so σ1 ≤ base_upper + change on the voxel.
    const double ub = upper ? (*upper)[i] + change : kInf;
    if (targets.unproven(ub, lb, distortion_of(ub, lb)) != DistortionTarget::kNone) return false;
    perturbed[i] = 1;
    perturbed_lower(i) = lb;
    perturbed_upper(i) = ub;
    return true;
  }
  // Locks the certifier's direction cache and makes it that of p.direction: ‖δ_e(Ξ d)‖ per edge, and no
  // voxel's rest computed yet when d changed. False when the first-order factors are not built (the solver
  // builds them where that pays: OctreeCertifier::direction_rest_pays).
  bool prepare_direction_rest(std::unique_lock<std::mutex>& lock) const {
    if (!im.first_built.load(std::memory_order_acquire)) return false;
    const MatS3& d = *p.direction;
    lock = std::unique_lock<std::mutex>(im.direction_mutex);
    if (im.direction.rows() == d.rows() && im.direction == d && im.direction_rest.size() == N) return true;
    im.direction = d;
    im.direction_delta = oc.edge_delta_norms(*im.reduction * d);
    im.direction_rest.setConstant(N, std::numeric_limits<double>::quiet_NaN());
    // Per group r_g Σ_e max_{i∈g} Θ¹_e(B_i) ‖δ_e(Ξ d)‖_F ≥ direction_rest(i) for every voxel i of group g
    // (the largest radius and factors of its voxels; the same rounding), all at once: most groups hold a
    // voxel that needs it, and one pass in group order reads the rows once.
    const long G = static_cast<long>(im.group_start.size()) - 1;
    im.group_rest.resize(G);
#pragma omp parallel for schedule(static)
    for (long q = 0; q < G; ++q)
      im.group_rest(q) = im.group_finite[q]
                             ? im.group_radius(q) * weighted_float_sum(im.direction_delta.data(),
                                                                       im.group_first.row(q).data(), E)
                             : kInf;
    return true;
  }
  // r_i Σ_e Θ¹_e(B_i) ‖δ_e(Ξ d)‖_F ≥ sup over B_i of ‖J(Ξ d)(q) − J(Ξ d)(c_i)‖_F (Step 2's (15) with the
  // first-order factors: a bound of the Hessian on the whole ball) for the cached direction d, computed on
  // first use (+∞ where a factor is). Rounding: docs/certificate.md, Step 4e.
  double direction_rest(long i) const {
    double& v = im.direction_rest(i);
    if (!std::isnan(v)) return v;
    const double sum =
        im.first_finite[i] ? weighted_float_sum(im.direction_delta.data(), im.first.row(i).data(), E) : kInf;
    v = oc.sampling_.radius_of(static_cast<int>(i)) * sum;
    return v;
  }
  // ≥ ‖ỹ − ỹ₀ − t d‖_F for the direction of CertifyParams (computed entrywise, each entry's rounding, ≤ 3u
  // of the magnitudes, added); −1 when no direction was passed or its sizes do not match (then only Γ_i ‖δ‖
  // is used).
  double direction_residual(const MatS3& y0) const {
    const MatS3* d = p.direction;
    const MatS3* D = p.direction_jacobians;
    const double t = p.direction_step;
    if (!d || !D || d->rows() != yr_rows || D->rows() != 3 * N || !(t >= 0) || !std::isfinite(t) ||
        !(p.direction_scale >= 0) || !std::isfinite(p.direction_scale) || yr_rows >= (1L << 20))
      return -1;
    constexpr double u = 0x1p-53;
    double r2 = 0;
    for (int a = 0; a < 3; ++a)
      for (long k = 0; k < yr_rows; ++k) {
        const double y = yr_ptr[a * yr_rows + k], y00 = y0(k, a), td = t * (*d)(k, a);
        const double e = std::abs((y - y00) - td) + 4 * u * (std::abs(y) + std::abs(y00) + std::abs(td));
        r2 += e * e;
      }
    // 1e-300: the product t·d's underflow (≤ 2⁻¹⁰⁷⁴ per entry; sums and differences do not underflow).
    const double rho = std::sqrt(r2) * (1 + 1e-12) + 1e-300;
    return std::isfinite(rho) ? rho : -1;
  }
  // ≥ ‖M‖₂ for a 3 by 3 block (the JT rows of one center): the smaller of ‖M‖_F and the root of Gershgorin's
  // bound on λ_max(MᵀM). Written out: Eigen's 3 x 3 temporaries of a block with a stride of 3N cost about a
  // tenth of the perturbation stage's per-voxel loop (docs/benchmarks.md, "The rest from a direction by voxel
  // groups").
  template <class Block>
  static double spectral_bound(const Block& M) {
    double a[3][3];  // a[c][r] = M(r, c): the columns
    for (int c = 0; c < 3; ++c)
      for (int r = 0; r < 3; ++r) a[c][r] = M(r, c);
    const auto dot = [&](int c, int d) { return a[c][0] * a[d][0] + a[c][1] * a[d][1] + a[c][2] * a[d][2]; };
    // The Gram matrix MᵀM: its diagonal (the trace is ‖M‖_F²) and off-diagonal magnitudes.
    const double g00 = dot(0, 0), g11 = dot(1, 1), g22 = dot(2, 2);
    const double g01 = std::abs(dot(0, 1)), g02 = std::abs(dot(0, 2)), g12 = std::abs(dot(1, 2));
    const double gersh = std::max({g00 + g01 + g02, g01 + g11 + g12, g02 + g12 + g22});
    return std::sqrt(std::min(g00 + g11 + g22, gersh));
  }

  // --- 1. J and H at the base centers: from the stored derivatives (CPU, or left to the backend's base
  // stage) or on the fly.
  void base_derivatives() {
    const auto t0 = Clock::now();
    scaleJ.resize(N);
    scaleH.resize(N);
    hnorm.resize(N);
    hop.setZero(N);
    lb2.setConstant(N, -kInf);
    tsb.assign(taylor ? N : 0, {});
    Hbase.clear();  // filled by stored_derivatives only (a backend's base stage keeps J and H on the device)
    Jc.resize(N);
    if (use_stored) {
      std::vector<double> Ycols = coefficient_columns();
      double cmax = 0;
      for (double v : Ycols) cmax = std::max(cmax, std::abs(v));
      for (long i = 0; i < N; ++i) {
        scaleJ(i) = im.scale_J(i) * cmax;
        scaleH(i) = im.scale_H(i) * cmax;
      }
      if (im.kernels && !combined) {
        // The backend's base stage also forms T (stage 3). The far field of the few voxels it leaves to
        // refine is built here from their stored rows: the device would evaluate every cage face per child.
        if (far_mode || fallback) stored_cols = Ycols;
        device_Y = std::move(Ycols);
      } else {
        stored_derivatives(Ycols);
        if (far_mode || fallback) stored_cols = std::move(Ycols);
      }
    } else {
#pragma omp parallel for schedule(dynamic, 64)
      for (long i = 0; i < N; ++i)
        eval_point(oc.sampling_.centers.row(i).transpose(), Jc[i], hnorm(i), scaleJ(i), scaleH(i), &hop(i),
                   oc.sampling_.radius_of(static_cast<int>(i)), &lb2(i), taylor ? &tsb[i] : nullptr);
    }
    cert.ms_jacobian = ms_since(t0);
  }
  // The coefficients as 3 contiguous columns of m doubles.
  std::vector<double> coefficient_columns() const {
    const long m = im.m;
    std::vector<double> Ycols(3 * m);
    for (long k = 0; k < m; ++k)
      for (int a = 0; a < 3; ++a) Ycols[a * m + k] = yr_ptr ? yr_ptr[a * yr_rows + k] : y(k, a);
    return Ycols;
  }
  std::vector<double> stored_cols;  // far mode: the coefficient columns (stored_hessian)
  // Rows first..first+count−1 of base center i's 9 stored derivative rows (3 gradient rows, then the
  // Hessian's xx, xy, xz, yy, yz, zz) times the coefficient columns: out[q][a].
  void stored_rows(long i, int first, int count, double (*out)[3]) const {
    const long m = im.m;
    float_rows_times_columns(im.GH.data() + static_cast<size_t>(i * 9 * m) + first * m, count,
                             stored_cols.data(), m, out);
  }
  // J at base center i (as stored_derivatives forms it), for the far fields when the backend's base stage
  // kept J on the device.
  Mat3 stored_jacobian(long i) const {
    double g3[3][3];
    stored_rows(i, 0, 3, g3);
    Mat3 J;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) J(a, b) = g3[b][a];
    return J;
  }
  // H at base center i from its 6 stored Hessian rows times the coefficients.
  void stored_hessian(long i, std::array<Mat3, 3>& H) const {
    double h6[6][3];
    stored_rows(i, 3, 6, h6);
    for (int a = 0; a < 3; ++a)
      H[a] << h6[0][a], h6[1][a], h6[2][a], h6[1][a], h6[3][a], h6[4][a], h6[2][a], h6[4][a], h6[5][a];
  }
  // J and ‖H‖ at every base center: the 9 stored rows of each voxel times the coefficient columns.
  void stored_derivatives(const std::vector<double>& Ycols) {
    const long m = im.m;
    if (taylor) Hbase.assign(N, {});
    const long ne = static_cast<long>(eval_list.size());
#pragma omp parallel for schedule(static)
    for (long k = 0; k < ne; ++k) {
      const long i = eval_list[k];
      const float* blk = im.GH.data() + static_cast<size_t>(i * 9 * m);
      double out[9][3];
      float_rows_times_columns(blk, 9, Ycols.data(), m, out);
      Mat3& J = Jc[i];
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) J(a, b) = out[b][a];
      double H6[3][6];
      for (int a = 0; a < 3; ++a)
        for (int q = 0; q < 6; ++q) H6[a][q] = out[3 + q][a];
      hnorm(i) = hessian_norm_sym(&H6[0][0], 6);
      if (combined || taylor) {
        std::array<Mat3, 3> H;
        for (int a = 0; a < 3; ++a)
          H[a] << H6[a][0], H6[a][1], H6[a][2], H6[a][1], H6[a][3], H6[a][4], H6[a][2], H6[a][4], H6[a][5];
        const double r = oc.sampling_.radius_of(static_cast<int>(i));
        if (combined) hop(i) = hessian_operator_norm(H);
        if (spectral) lb2(i) = taylor_sigma3_lower_bound(J, H, r);
        if (taylor) Hbase[i] = H;
      }
    }
  }

  // --- 2. σ3 at the base centers (on the device, stage 3 computes it with T).
  void base_sigma3() {
    const auto t0 = Clock::now();
    sigma3.resize(N);
    sigma1.setConstant(N, std::numeric_limits<double>::quiet_NaN());
    sign_unresolved.assign(N, 0);
    if (device_Y.empty()) {
      // kSvdLanes evaluated centers at a time (SIMD lanes; a center's values do not depend on its lane's
      // company).
      for (long i = 0; i < N; ++i)
        if (!evaluated(i)) sigma3(i) = std::numeric_limits<double>::quiet_NaN();
      const long ne = static_cast<long>(eval_list.size());
      const long groups = (ne + kSvdLanes - 1) / kSvdLanes;
#pragma omp parallel for schedule(static)
      for (long g = 0; g < groups; ++g) {
        long idx[kSvdLanes];
        Mat3 J[kSvdLanes];
        int n = 0;
        for (long k = g * kSvdLanes; k < std::min(ne, (g + 1) * kSvdLanes); ++k) {
          idx[n] = eval_list[k];
          J[n] = Jc[idx[n]];
          ++n;
        }
        Vec3 sv[kSvdLanes];
        bool resolved[kSvdLanes];
        signed_singular_values_lanes(J, n, sv, resolved);
        for (int k = 0; k < n; ++k) {
          sigma3(idx[k]) = sv[k](2);
          sigma1(idx[k]) = sv[k](0);
          sign_unresolved[idx[k]] = !resolved[k];
        }
      }
    }
    cert.ms_sigma = ms_since(t0);
  }

  // Octree level of base voxel i below the base grid (mesh domain; 0 for the paper's grid).
  int level(long i) const {
    return oc.sampling_.level.empty() ? 0 : oc.sampling_.level[i];
  }
  std::vector<long> uncleared;    // base voxels refused by the guard
  std::vector<long> taylor_base;  // base voxels whose Lipschitz bounds do not prove a target (Step 3d)

  // --- 3. Lipschitz constants of the base voxels: δ norms (map) times the per-voxel per-edge factors (cage
  // only), and condition (6) for each base voxel.
  void base_bounds() {
    const auto t0 = Clock::now();
    delta = oc.delta_norms(fm);
    const auto& factors = oc.factor_matrix(third);
    T.resize(N);
    double device_ms = 0;
    const bool on_device = !device_Y.empty();
    if (on_device) {
      // σ3, ‖H‖ and T in one pass on the device (its time is reported as the Jacobian stage).
      bool& has = third ? im.kernels_third : im.kernels_first;
      if (!has) {
        im.kernels->set_factors(third, factors.data(), E);
        has = true;
      }
      const auto td = Clock::now();
      im.kernels->base_stage(device_Y.data(), third, delta, sigma3, sigma1, hnorm, T, sign_unresolved);
      device_ms = ms_since(td);
      cert.ms_jacobian += device_ms;
    }
    if (!on_device) factor_sums(factors, third ? im.third_finite : im.first_finite, T);
    if (combined) factor_sums(oc.factor_matrix(false), im.first_finite, T1);
    const VecXd& Tf = combined ? T1 : T;  // first-order sums (first, combined)
    cert.min_sigma3_center = kInf;
    for (long i = 0; i < N; ++i)
      if (evaluated(i)) cert.min_sigma3_center = std::min(cert.min_sigma3_center, sigma3(i));
    const double base_storage = use_stored ? kFloatStorageRel : 0.0;
    base.resize(N);
    // Each voxel's leaf in parallel (dynamic chunks: the evaluated voxels cluster), then the lists in voxel
    // order.
    enum : char { kFails = 1, kTaylor = 2 };
    std::vector<char> flags(N, 0);
#pragma omp parallel for schedule(dynamic, 512)
    for (long i = 0; i < N; ++i) {
      if (!evaluated(i)) {
        const double nan = std::numeric_limits<double>::quiet_NaN();
        base[i] = {oc.sampling_.centers.row(i).transpose(),
                   oc.sampling_.side_of(static_cast<int>(i)),
                   level(i),
                   nan,
                   nan,
                   perturbed_lower(i),
                   true,
                   static_cast<int>(i),
                   false};
        base[i].sigma1_upper = perturbed_upper(i);
        base[i].distortion_upper = distortion_of(perturbed_upper(i), perturbed_lower(i));
        continue;
      }
      const double r = oc.sampling_.radius_of(static_cast<int>(i));
      const double L = lipschitz(hnorm(i), taylor_part(hop(i), sigma3(i), lb2(i), r), Tf(i), T(i), r);
      const double lb = sigma3(i) - r * L;
      // Not clear of the cage: refused (the bound's argument needs the ball inside the cage's interior).
      const double margin =
          im.clear[i] ? lb - tolerance(scaleJ(i), scaleH(i), sigma3(i), L, r, base_storage) : -kInf;
      base[i] = {oc.sampling_.centers.row(i).transpose(), oc.sampling_.side_of(static_cast<int>(i)), level(i),
                 sigma3(i), L, margin, margin > 0, static_cast<int>(i), sign_unresolved[i] != 0,
                 // σ3 from the float-stored derivatives: within the storage allowance of the exact one
                 // (Step 5), which the margin already subtracts; reported like the far field's eps_J.
                 base_storage * scaleJ(i)};
      // J's Lipschitz constant: L without the spectral bound's σ3-specific Taylor term (hop(i) is ‖H‖_op).
      double L1 = lipschitz(hnorm(i), hop(i), Tf(i), T(i), r);
      if (fallback && !(margin > 0) && im.clear[i] && sigma3(i) > 0 && !sign_unresolved[i] &&
          spectral_fallback(i, r, base_storage, base[i], L1))
        fallback_count.fetch_add(1, std::memory_order_relaxed);
      set_distortion(base[i], sigma1(i), 0.0, L1, r, scaleJ(i), scaleH(i), base_storage);
      if (taylor && unproven(base[i]) != DistortionTarget::kNone) flags[i] |= kTaylor;
      if (!(base[i].margin > 0)) flags[i] |= kFails;
    }
    cert.fallback_voxels = fallback_count.load();
    cert.spectral_fallback = fallback;
    for (long i = 0; i < N; ++i) {
      if (flags[i] & kTaylor) taylor_base.push_back(i);
      if (flags[i] & kFails) failing_base.push_back(i);
    }
    // Step 3d where the Lipschitz bounds do not prove a target (a few percent of the voxels near a binding
    // target): forming the bounds at every center would cost more than the refinement they save.
    const long nt = static_cast<long>(taylor_base.size());
#pragma omp parallel for schedule(dynamic, 64)
    for (long k = 0; k < nt; ++k) {
      const long i = taylor_base[k];
      const double r = oc.sampling_.radius_of(static_cast<int>(i));
      if (!Hbase.empty()) tsb[i] = taylor_singular_bounds(Jc[i], Hbase[i], r);
      const double L1 = lipschitz(hnorm(i), hop(i), Tf(i), T(i), r);
      set_distortion(base[i], sigma1(i), 0.0, L1, r, scaleJ(i), scaleH(i), base_storage, &tsb[i], T(i));
    }
    taylor_base.clear();
    cert.ms_bound = ms_since(t0) - device_ms;
  }
  // Step 4f: the spectral bound's loss (Step 3c; the first-order term where its factors are built) at a base
  // voxel the third-order bound leaves unproven, from the same stored J̃, H̃ and third-order sum T(i) as the
  // spectral bound's base stage (so the same rounding allowances: τ with the float storage, Step 5). Where
  // it proves the voxel, `leaf` takes its L and margin and `L1` the combined bound's Lipschitz constant of J
  // (σ1's bound); true then.
  std::atomic<long> fallback_count{0};
  bool spectral_fallback(long i, double r, double storage, CertLeaf& leaf, double& L1) const {
    std::array<Mat3, 3> H;
    stored_hessian(i, H);
    const double hop_i = hessian_operator_norm(H);
    // J̃ as the base stage formed it (a backend's base stage kept it on the device: the same stored rows
    // here).
    const double lb_i = taylor_sigma3_lower_bound(device_Y.empty() ? Jc[i] : stored_jacobian(i), H, r);
    double t1 = kInf;
    if (im.first_built.load(std::memory_order_acquire)) t1 = first_order_sum(i);
    const double L = std::min(t1, taylor_part(hop_i, sigma3(i), lb_i, r) + 0.5 * r * T(i));
    const double margin = sigma3(i) - r * L - tolerance(scaleJ(i), scaleH(i), sigma3(i), L, r, storage);
    if (!(margin > 0)) return false;
    leaf.L = L;
    leaf.margin = margin;
    leaf.certified = true;
    L1 = std::min(t1, hop_i + 0.5 * r * T(i));
    return true;
  }
  // Σ_e δ_e Γ_e(B_i) from voxel i's row of first-order factors (factor_sums for one voxel).
  double first_order_sum(long i) const { return factor_row_sum(im.first.row(i).data(), im.first_finite[i]); }
  // Σ_e δ_e f_e for one row of factors. An edge whose factor is +∞ (the voxel's ball may touch it) makes the
  // sum infinite unless δ_e = 0 exactly (then H does not depend on it). Rows without an infinite factor take a
  // branch-free, vectorized dot product.
  double factor_row_sum(const float* f, bool finite) const {
    if (finite) return weighted_float_sum(delta.data(), f, E);
    double s = 0;  // an infinite factor counts only where its edge moved (0 · ∞ would be NaN)
    for (long e = 0; e < E; ++e)
      if (delta(e) != 0) s += delta(e) * static_cast<double>(f[e]);
    return s;
  }
  // T_i = Σ_e δ_e F(i, e) for every evaluated base voxel (factor_row_sum).
  void factor_sums(const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>& factors,
                   const std::vector<char>& row_finite, VecXd& out) const {
    out.setZero(N);
    const long ne = static_cast<long>(eval_list.size());
#pragma omp parallel for schedule(static)
    for (long k = 0; k < ne; ++k) {
      const long i = eval_list[k];
      out(i) = factor_row_sum(factors.row(i).data(), row_finite[i] != 0);
    }
  }
  // --- 4. Adaptive refinement of the failing voxels, one octree level at a time: all nodes of a level are
  // evaluated in one batch (on the backend when it has kernels), then the decisions are taken here in
  // base-voxel order, so the result does not depend on the thread schedule or the backend. Every child keeps
  // the smaller of its parent's and its own bound (its ball lies inside the parent's). A voxel is certified
  // iff every node of its subtree resolves; the set of evaluated nodes is the same as in a depth-first
  // traversal whenever no budget runs out, so the order changes no verdict.
  void refine() {
    const auto t0 = Clock::now();
    const long F = static_cast<long>(failing_base.size());
    vs.resize(F);
    std::vector<long> refinable;
    for (long fi = 0; fi < F; ++fi) {
      const long i = failing_base[fi];
      if (!im.clear[i]) uncleared.push_back(i);
      if (!im.clear[i] || sigma3(i) <= 0 || p.max_depth == 0) {
        vs[fi].ok = false;  // refused, or σ3 ≤ 0 at a center: no subdivision can certify it
        vs[fi].failed_here = true;
        if (p.stop_on_failure) abort = true;
        continue;
      }
      refinable.push_back(fi);
    }
    // With a priority list (line search), its voxels are refined first, to completion; the others only if
    // they all pass. A voxel left unrefined after an abort keeps its failing base leaf (not certified).
    std::vector<long> first, rest;
    if (p.stop_on_failure && !p.priority_voxels.empty()) {
      std::vector<long> prio = p.priority_voxels;
      std::sort(prio.begin(), prio.end());
      for (long fi : refinable)
        (std::binary_search(prio.begin(), prio.end(), failing_base[fi]) ? first : rest).push_back(fi);
    } else {
      rest = refinable;
    }
    for (const std::vector<long>* phase : {&first, &rest}) {
      if (p.stop_on_failure && abort) break;
      std::vector<int> far_of;
      if (far_mode) base_far_fields(*phase, far_of);
      for (size_t k = 0; k < phase->size(); ++k) {
        const long fi = (*phase)[k];
        const long i = failing_base[fi];
        vs[fi].first_child = add_children(base[i].center, base[i].side, 0, T(i), combined ? T1(i) : 0.0, fi,
                                          far_mode ? far_of[k] : -1);
      }
      refine_frontier();
    }
    cert.ms_refine = ms_since(t0);
  }
  // Level-synchronous refinement of the nodes in `frontier` until none is left (or an abort).
  void refine_frontier() {
    std::vector<int> batch;
    std::vector<NodeValues> vals;
    while (!frontier.empty()) {
      if (p.stop_on_failure && abort) {
        for (int id : frontier) unresolved(tree[id]);
        frontier.clear();
        break;
      }
      take_batch(batch);
      evaluate_batch(batch, vals);
      frontier.clear();
      decide_batch(batch, vals);
      if (far_mode) {
        // The batch's parents' far fields were last needed to build their children's (decide_batch).
        for (int id : batch)
          if (tree[id].far >= 0) far[tree[id].far] = FarField{};
      }
    }
  }
  int add_children(const Vec3& c, double sd, int depth, double bound, double bound_first, long fi,
                   int far_index = -1) {
    const int first = static_cast<int>(tree.size());
    for (int k = 0; k < 8; ++k) {
      const Vec3 off((k & 1 ? 0.25 : -0.25), (k & 2 ? 0.25 : -0.25), (k & 4 ? 0.25 : -0.25));
      tree.push_back({c + sd * off, sd / 2, depth + 1, bound, bound_first, fi, -1, {}, far_index});
      frontier.push_back(first + k);
    }
    return first;
  }
  // A leaf with unknown σ3 keeps the leaves a tiling of the voxel.
  void unresolved(Node& nd) {
    const long bi = failing_base[nd.fi];
    nd.leaf = {nd.c,  nd.side, level(bi) + nd.depth, std::numeric_limits<double>::quiet_NaN(), kInf,
               -kInf, false,   static_cast<int>(bi)};
    vs[nd.fi].ok = false;
  }
  // The frontier's nodes within the budgets, in order; the others become unresolved leaves.
  void take_batch(std::vector<int>& batch) {
    batch.clear();
    for (int id : frontier) {
      Node& nd = tree[id];
      VoxelState& st = vs[nd.fi];
      if (st.definite_fail || ++st.evaluated > p.max_children_per_voxel ||
          budget_used++ >= p.max_refined_voxels) {
        if (!st.definite_fail) budget_hit = true;
        if (st.evaluated > p.max_children_per_voxel) st.failed_here = true;
        unresolved(nd);
        if (p.stop_on_failure) abort = true;
        continue;
      }
      batch.push_back(id);
    }
  }
  // σ3, ‖H‖ and the node's own bound at every node of the batch.
  void evaluate_batch(const std::vector<int>& batch, std::vector<NodeValues>& vals) const {
    const long nb = static_cast<long>(batch.size());
    vals.assign(nb, {});
    if (far_mode) {  // before the backend's node kernel: the far field is cheaper than every face per child
      evaluate_far_batch(batch, vals);
      return;
    }
    if (im.kernels && !combined && nb > 0) {
      MatX3d bc(nb, 3);
      VecXd brad(nb);
      for (long q = 0; q < nb; ++q) {
        bc.row(q) = tree[batch[q]].c.transpose();
        brad(q) = 0.5 * std::sqrt(3.0) * tree[batch[q]].side;
      }
      im.kernels->evaluate_nodes(fm.A, fm.AD, fm.A_abs, delta, third, bc, brad, vals);
      return;
    }
    if (p.refinement != RefinementEval::kPerFace) {
      full_data();
      if (p.refinement == RefinementEval::kPerEdge) {
#pragma omp parallel for schedule(dynamic, 4)
        for (long q = 0; q < nb; ++q) evaluate_node_per_edge(tree[batch[q]], vals[q]);
        return;
      }
      // Consecutive groups of kLanes nodes (the 8 children of a node, when no budget cut the batch); each
      // node's values depend on the node only, so neither the grouping nor the thread count changes them.
      in_lane_groups(
          nb,
          [&](long q, Vec3& c, double& rad) {
            c = tree[batch[q]].c;
            rad = 0.5 * std::sqrt(3.0) * tree[batch[q]].side;
          },
          [&](const Vec3* c, const double* rad, int n, long q0) {
            EdgeJet::Values ev[EdgeJet::kLanes];
            im.edge_jet->evaluate_lanes(*edge_data, c, rad, n, third, !third || combined, third, ev);
            for (int k = 0; k < n; ++k) node_values(ev[k], rad[k], vals[q0 + k]);
          });
      return;
    }
#pragma omp parallel for schedule(dynamic, 4)
    for (long q = 0; q < nb; ++q) {
      const Node& nd = tree[batch[q]];
      const double rad = 0.5 * std::sqrt(3.0) * nd.side;
      Mat3 J;
      NodeValues& v = vals[q];
      double lb = -kInf;
      eval_point(nd.c, J, v.hnorm, v.scale_J, v.scale_H, &v.hnorm_op, rad, &lb, &v.taylor);
      bool resolved = true;
      const Vec3 sv = signed_singular_values(J, &resolved);
      v.sigma3 = sv(2);
      v.sigma1 = sv(0);
      v.sign_unresolved = !resolved;
      v.hnorm_op_j = v.hnorm_op;
      v.hnorm_op = taylor_part(v.hnorm_op, v.sigma3, lb, rad);
      double own = 0;
      for (long e = 0; e < E; ++e)
        if (delta(e) != 0)
          own += delta(e) * (third ? third_order_edge_factor(im.eu[e], im.ew[e], nd.c, rad)
                                   : first_order_edge_factor(im.eu[e], im.ew[e], nd.c, rad));
      v.own_bound = own;
      if (combined) {
        double own1 = 0;
        for (long e = 0; e < E; ++e)
          if (delta(e) != 0) own1 += delta(e) * first_order_edge_factor(im.eu[e], im.ew[e], nd.c, rad);
        v.own_first = own1;
      }
    }
  }
  // One node through the per-edge representation (edge_jet.h): J, H and both factor sums in one pass.
  void evaluate_node_per_edge(const Node& nd, NodeValues& v) const {
    const double rad = 0.5 * std::sqrt(3.0) * nd.side;
    EdgeJet::Values ev;
    im.edge_jet->evaluate(*edge_data, nd.c, rad, third, !third || combined, third, ev);
    node_values(ev, rad, v);
  }
  // σ3 (signed SVD), ‖H‖ and the node's own bound from one node's per-edge values.
  void node_values(const EdgeJet::Values& ev, double rad, NodeValues& v) const {
    v.scale_J = ev.scale_J;
    v.scale_H = ev.scale_H;
    bool resolved = true;
    const Vec3 sv = signed_singular_values(ev.J, &resolved);
    v.sigma3 = sv(2);
    v.sigma1 = sv(0);
    v.sign_unresolved = !resolved;
    if (third) v.hnorm = std::sqrt(ev.H[0].squaredNorm() + ev.H[1].squaredNorm() + ev.H[2].squaredNorm());
    if (combined) v.hnorm_op = hessian_operator_norm(ev.H);
    v.hnorm_op_j = v.hnorm_op;
    if (spectral)
      v.hnorm_op = taylor_part(v.hnorm_op, v.sigma3, taylor_sigma3_lower_bound(ev.J, ev.H, rad), rad);
    v.own_bound = third ? ev.T_third : ev.T_first;
    v.own_first = ev.T_first;
    if (taylor) v.taylor = taylor_singular_bounds(ev.J, ev.H, rad);
  }
  // Runs `eval(c, rad, n, first)` on consecutive groups of at most kLanes of `count` items (items first ..
  // first + n − 1), `point(k, c, rad)` giving item k's center and ball radius: one SIMD pass of
  // EdgeJet::evaluate_lanes per group, the groups in parallel. With a single group no parallel region is
  // opened: its fork and join can cost more than the group itself on a busy machine (animal, first bound, 8
  // children: refine 0.7 ms at 1 thread, 9.7 ms at 2).
  template <class Point, class Eval>
  static void in_lane_groups(long count, const Point& point, const Eval& eval) {
    constexpr long W = EdgeJet::kLanes;
    const long groups = (count + W - 1) / W;
#pragma omp parallel for schedule(dynamic, 1) if (groups > 1)
    for (long g = 0; g < groups; ++g) {
      const long first = g * W;
      const int n = static_cast<int>(std::min(W, count - first));
      Vec3 c[W];
      double rad[W];
      for (int k = 0; k < n; ++k) point(first + k, c[k], rad[k]);
      eval(c, rad, n, first);
    }
  }
  mutable std::unique_ptr<EdgeJet::MapData> edge_data;  // built on the first refinement batch
  mutable std::once_flag edge_data_once;
  // Thread-safe: the far-field batch needs it only for its rare exact re-evaluations, from inside a parallel
  // loop (on the animal's cage preparing it costs 0.3 ms, more than a far-field level of 88 children).
  const EdgeJet::MapData& full_data() const {
    std::call_once(edge_data_once,
                   [&] { edge_data = std::make_unique<EdgeJet::MapData>(im.edge_jet->prepare(fm)); });
    return *edge_data;
  }

  // --- 4d. Far-field refinement (docs/certificate.md, Step 4d).
  std::vector<FarField> far;
  mutable std::vector<Jet> batch_jets;  // J̃, H̃ of the last evaluated batch's nodes (far mode)
  // Groups of consecutive batch nodes with the same parent far field (at most kLanes): far-field groups when
  // it is usable, else (none: the tight-lower-bound stage; or T_far infinite) evaluated exactly in SIMD
  // lanes; a node whose σ3 does not clear its eps_J is evaluated again exactly, so that "σ3 ≤ 0 at a center"
  // is never said of an approximation.
  void evaluate_far_batch(const std::vector<int>& batch, std::vector<NodeValues>& vals) const {
    const long nb = static_cast<long>(batch.size());
    batch_jets.assign(nb, Jet{});
    std::vector<char> redo(nb, 0);
    std::vector<std::pair<long, int>> groups;  // (first, count)
    for (long q = 0; q < nb;) {
      long e = q + 1;
      while (e < nb && e - q < EdgeJet::kLanes && tree[batch[e]].far == tree[batch[q]].far) ++e;
      groups.push_back({q, static_cast<int>(e - q)});
      q = e;
    }
    const long ng = static_cast<long>(groups.size());
#pragma omp parallel for schedule(dynamic, 1) if (ng > 1)
    for (long g = 0; g < ng; ++g) {
      const long q0 = groups[g].first;
      const int n = groups[g].second;
      constexpr int W = EdgeJet::kLanes;
      Vec3 c[W];
      double rad[W];
      for (int k = 0; k < n; ++k) {
        c[k] = tree[batch[q0 + k]].c;
        rad[k] = 0.5 * std::sqrt(3.0) * tree[batch[q0 + k]].side;
      }
      EdgeJet::Values ev[W];
      const int fidx = tree[batch[q0]].far;
      const FarField* ff = fidx >= 0 && far[fidx].ok ? &far[fidx] : nullptr;
      if (!ff) {
        im.edge_jet->evaluate_lanes(full_data(), c, rad, n, true, false, true, ev);
        for (int k = 0; k < n; ++k) exact_values(ev[k], rad[k], vals[q0 + k], batch_jets[q0 + k]);
        continue;
      }
      im.edge_jet->evaluate_lanes(ff->patch, c, rad, n, true, false, true, ev);
      for (int k = 0; k < n; ++k) {
        NodeValues& v = vals[q0 + k];
        far_values(*ff, c[k], ev[k], v, batch_jets[q0 + k]);
        // Again exactly when σ3 does not clear eps_J (so that σ3 ≤ 0 is only said of an exact value), or
        // when the node fails only because of the far field's own terms: without eps_J, eps_H and the far
        // part of its bound it would pass, so an exact evaluation may certify it here instead of splitting
        // it (deep in the octree the far field's terms, inherited from coarser balls, no longer shrink).
        const Node& nd = tree[batch[q0 + k]];
        const double own = std::min(nd.bound, v.own_bound);
        if (!(v.sigma3 > v.eps_J) ||
            (!(third_margin(nd, v, own, v.eps_J, v.eps_H) > 0) &&
             (nd.depth >= p.max_depth || third_margin(nd, v, std::min(nd.bound, ev[k].T_third), 0, 0) > 0)))
          redo[q0 + k] = 1;
      }
    }
    // The exact re-evaluations, 8 nodes per SIMD pass.
    std::vector<long> again;
    for (long q = 0; q < nb; ++q)
      if (redo[q]) again.push_back(q);
    const long na = static_cast<long>(again.size());
    in_lane_groups(
        na,
        [&](long k, Vec3& c, double& rad) {
          c = tree[batch[again[k]]].c;
          rad = 0.5 * std::sqrt(3.0) * tree[batch[again[k]]].side;
        },
        [&](const Vec3* c, const double* rad, int n, long k0) {
          EdgeJet::Values ev[EdgeJet::kLanes];
          im.edge_jet->evaluate_lanes(full_data(), c, rad, n, true, false, true, ev);
          for (int k = 0; k < n; ++k)
            exact_values(ev[k], rad[k], vals[again[k0 + k]], batch_jets[again[k0 + k]]);
        });
  }
  // Condition (6)'s margin with the third-order bound (as decide_batch forms it) for a node's values with
  // the given own bound and far-field errors.
  double third_margin(const Node& nd, const NodeValues& v, double own, double eps_J, double eps_H) const {
    const double rad = 0.5 * std::sqrt(3.0) * nd.side;
    return node_margin(v, eps_J, v.hnorm + eps_H + rad * own, rad);
  }
  // Condition (6) at a refinement node: σ3 − eps_J − rad L − τ (eps_J: the far field's error of σ3, 0 for an
  // exact evaluation).
  static double node_margin(const NodeValues& v, double eps_J, double L, double rad) {
    return v.sigma3 - eps_J - rad * L - tolerance(v.scale_J, v.scale_H, v.sigma3, L, rad, 0.0);
  }
  void exact_values(const EdgeJet::Values& ev, double rad, NodeValues& v, Jet& jet) const {
    node_values(ev, rad, v);
    v.eps_J = v.eps_H = 0;
    jet.J = ev.J;
    jet.H = ev.H;
  }
  // A child at c from its near faces' values `ev` (J_N, H_N, T_N over its own ball) and the parent's far
  // field:
  //   J̃ = J_N(c) + J̃_far + H̃_far[Δ],  H̃ = H_N(c) + H̃_far,  Δ = c − c_P,
  //   eps_J = eps_J,P + |Δ| eps_H,P + ½|Δ|² T,  eps_H = eps_H,P + |Δ| T,  own bound = T_N + T
  // (the child's ball lies in the parent's, where T bounds the far part's third derivative).
  void far_values(const FarField& ff, const Vec3& c, const EdgeJet::Values& ev, NodeValues& v,
                  Jet& jet) const {
    const Vec3 d = c - ff.c;
    const double dn = d.norm();
    jet.J = ev.J + ff.J;
    for (int a = 0; a < 3; ++a) {
      jet.J.row(a) += (ff.H[a] * d).transpose();
      jet.H[a] = ev.H[a] + ff.H[a];
    }
    bool resolved = true;
    const Vec3 sv = signed_singular_values(jet.J, &resolved);
    v.sigma3 = sv(2);
    v.sigma1 = sv(0);
    v.sign_unresolved = !resolved;
    v.hnorm = std::sqrt(jet.H[0].squaredNorm() + jet.H[1].squaredNorm() + jet.H[2].squaredNorm());
    v.eps_J = ff.eps_J + dn * ff.eps_H + 0.5 * dn * dn * ff.T;
    v.eps_H = ff.eps_H + dn * ff.T;
    v.scale_J = ev.scale_J + ff.scale_J + dn * ff.scale_H;
    v.scale_H = ev.scale_H + ff.scale_H;
    v.own_bound = ev.T_third + ff.T;
    v.own_first = 0;
    v.hnorm_op = 0;
  }
  // The far field of a subdivided node (center c, radius rad, values v, jet) whose own parent's far field is
  // `parent` (nullptr: a base voxel or an exactly evaluated parent; then T is summed over every edge, from
  // the base voxel's factor row `row` when given).
  void build_far(FarField& ff, const Vec3& c, double rad, const NodeValues& v, const Jet& jet,
                 const FarField* parent, const float* row) const {
    ff.c = c;
    const bool inherit = parent && parent->ok;
    im.edge_jet->faces_near(c, p.far_field_reach * rad, inherit ? &parent->near : nullptr, ff.near);
    im.edge_jet->make_patch(fm, ff.near, ff.patch);
    EdgeJet::Values ev;
    im.edge_jet->evaluate(ff.patch, c, rad, true, false, false, ev);
    ff.J = jet.J - ev.J;
    for (int a = 0; a < 3; ++a) ff.H[a] = jet.H[a] - ev.H[a];
    ff.eps_J = v.eps_J;
    ff.eps_H = v.eps_H;
    ff.scale_J = v.scale_J + ev.scale_J;
    ff.scale_H = v.scale_H + ev.scale_H;
    ff.T = inherit ? parent->T + ring_T(parent->near, ff.near, c, rad) : far_T(ff.near, c, rad, row);
    ff.ok = std::isfinite(ff.T);
  }
  // ‖A_t‖_F, and per edge the norm of δ_e restricted to a set of faces (`in`: membership marks).
  double face_norm(int t) const {
    return fm.A[t].norm();
  }
  double restricted_delta(int e, const std::vector<char>& in) const {
    const CageEdge& ce = oc.cage_.edges[e];
    const bool i0 = in[ce.f0] != 0, i1 = in[ce.f1] != 0;
    return i0 && i1 ? delta(e) : i0 ? face_norm(ce.f0) : i1 ? face_norm(ce.f1) : 0.0;
  }
  // Σ_e ‖δ_e^far‖ Θ_e(B(c, rad)) over every edge, far = the faces not in `near` (sorted): a bound of the far
  // part's third derivative on the ball (Step 2's (20) for the faces of the far part).
  double far_T(const std::vector<int>& near, const Vec3& c, double rad, const float* row) const {
    thread_local std::vector<char> in;
    in.assign(oc.cage_.num_faces(), 1);
    for (int t : near) in[t] = 0;
    double s = 0;
    for (long e = 0; e < E; ++e) {
      const double w = restricted_delta(static_cast<int>(e), in);
      if (w == 0) continue;
      const double th =
          row ? static_cast<double>(row[e]) : third_order_edge_factor(im.eu[e], im.ew[e], c, rad);
      s += w * th;
    }
    return s;
  }
  // Σ over the edges of the ring R = old \ now (the faces that were near the parent and are far from this
  // node) of ‖δ_e^R‖ Θ_e(B(c, rad)): the far part grows by F_R (both lists ascending).
  double ring_T(const std::vector<int>& old, const std::vector<int>& now, const Vec3& c, double rad) const {
    thread_local std::vector<char> in, seen;
    if (in.size() != static_cast<size_t>(oc.cage_.num_faces())) in.assign(oc.cage_.num_faces(), 0);
    if (seen.size() != static_cast<size_t>(E)) seen.assign(E, 0);
    std::vector<int> ring;
    std::set_difference(old.begin(), old.end(), now.begin(), now.end(), std::back_inserter(ring));
    for (int t : ring) in[t] = 1;
    double s = 0;
    for (int t : ring)
      for (int e : im.edge_jet->face_edges(t)) {
        if (seen[e]) continue;
        seen[e] = 1;
        const double w = restricted_delta(e, in);
        if (w != 0) s += w * third_order_edge_factor(im.eu[e], im.ew[e], c, rad);
      }
    for (int t : ring) {
      in[t] = 0;
      for (int e : im.edge_jet->face_edges(t)) seen[e] = 0;
    }
    return s;
  }
  // Base voxel i's far field (ball radius rad, its J̃, H̃ and errors). The children's balls must lie in the
  // ball: |Δ| + r_child = the voxel's half-diagonal ≤ rad, up to the rounding of the radii (relative 1e-12
  // here; it moves a factor by as little, within τ).
  void base_far(FarField& ff, long i, double rad, const NodeValues& v, const Jet& jet,
                const FactorMatrix* rows) const {
    build_far(ff, base[i].center, rad, v, jet, nullptr, rows ? rows->row(i).data() : nullptr);
    if (rad < 0.5 * std::sqrt(3.0) * base[i].side * (1 - 1e-12)) ff.ok = false;
  }
  // The far fields of the base voxels about to be refined (failing_base indices `fis`): J and H at their
  // centers exactly (8 voxels per SIMD pass), T from their factor rows. far_of[k] indexes `far`.
  void base_far_fields(const std::vector<long>& fis, std::vector<int>& far_of) {
    const long n = static_cast<long>(fis.size());
    far_of.resize(n);
    const size_t first = far.size();
    far.resize(first + n);
    for (long k = 0; k < n; ++k) far_of[k] = static_cast<int>(first + k);
    const FactorMatrix* rows = im.third.rows() == N ? &im.third : nullptr;
    if (use_stored && !stored_cols.empty()) {
      // J̃ and H̃ from the stored derivatives (J as the base stage computed it, H from the 6 stored Hessian
      // rows): within the float-storage allowance of the exact values (Step 5), which becomes eps_J, eps_H.
#pragma omp parallel for schedule(dynamic, 4) if (n > 1)
      for (long k = 0; k < n; ++k) {
        const long i = failing_base[fis[k]];
        NodeValues v;
        v.scale_J = scaleJ(i);
        v.scale_H = scaleH(i);
        v.eps_J = kFloatStorageRel * scaleJ(i);
        v.eps_H = kFloatStorageRel * scaleH(i);
        Jet jet;
        jet.J = device_Y.empty() ? Jc[i] : stored_jacobian(i);
        stored_hessian(i, jet.H);
        base_far(far[first + k], i, oc.sampling_.radius_of(static_cast<int>(i)), v, jet, rows);
      }
      return;
    }
    in_lane_groups(
        n,
        [&](long k, Vec3& c, double& rad) {
          const long i = failing_base[fis[k]];
          c = base[i].center;
          rad = oc.sampling_.radius_of(static_cast<int>(i));
        },
        [&](const Vec3* c, const double* rad, int m, long k0) {
          EdgeJet::Values ev[EdgeJet::kLanes];
          im.edge_jet->evaluate_lanes(full_data(), c, rad, m, true, false, false, ev);
          for (int k = 0; k < m; ++k) {
            const long i = failing_base[fis[k0 + k]];
            NodeValues v;
            v.scale_J = ev[k].scale_J;
            v.scale_H = ev[k].scale_H;
            base_far(far[first + k0 + k], i, rad[k], v, Jet{ev[k].J, ev[k].H}, rows);
          }
        });
  }
  // Condition (6) at each node of the batch, in order: a certified leaf, a failed leaf, or 8 children.
  void decide_batch(const std::vector<int>& batch, const std::vector<NodeValues>& vals) {
    for (size_t q = 0; q < batch.size(); ++q) {
      const int id = batch[q];
      const NodeValues& v = vals[q];
      const long fi = tree[id].fi;
      VoxelState& st = vs[fi];
      const Vec3 c = tree[id].c;
      const double sd = tree[id].side;
      const int depth = tree[id].depth;
      st.depth_used = std::max(st.depth_used, depth);
      st.min_sigma = std::min(st.min_sigma, v.sigma3);
      const double rad = 0.5 * std::sqrt(3.0) * sd;
      const double bnd = std::min(tree[id].bound, v.own_bound);
      const double bnd1 = combined ? std::min(tree[id].bound_first, v.own_first) : bnd;
      const double L = lipschitz(v.hnorm + v.eps_H, v.hnorm_op, bnd1, bnd, rad);
      const double margin = node_margin(v, v.eps_J, L, rad);
      const int bi = static_cast<int>(failing_base[fi]);
      const int leaf_depth = level(bi) + depth;
      const double L1 = lipschitz(v.hnorm + v.eps_H, v.hnorm_op_j, bnd1, bnd, rad);
      if (margin > 0) {
        tree[id].leaf = {c, sd, leaf_depth, v.sigma3, L, margin, true, bi, v.sign_unresolved, v.eps_J};
        set_distortion(tree[id].leaf, v.sigma1, v.eps_J, L1, rad, v.scale_J, v.scale_H, 0.0, &v.taylor,
                       v.own_bound);
      } else if (v.sigma3 <= 0 || depth >= p.max_depth || (p.stop_on_failure && abort)) {
        tree[id].leaf = {c, sd, leaf_depth, v.sigma3, L, margin, false, bi, v.sign_unresolved, v.eps_J};
        set_distortion(tree[id].leaf, v.sigma1, v.eps_J, L1, rad, v.scale_J, v.scale_H, 0.0, &v.taylor,
                       v.own_bound);
        st.ok = false;
        if (v.sigma3 <= 0 || depth >= p.max_depth) st.failed_here = true;
        // σ3 ≤ 0 (or a sign not resolved, σ3 = 0) at a center settles this voxel: refining its other nodes
        // cannot change the verdict.
        if (v.sigma3 <= 0) st.definite_fail = true;
        if (p.stop_on_failure) abort = true;
      } else {
        ++st.refined;
        int far_index = -1;
        if (far_mode) {
          far_index = static_cast<int>(far.size());
          far.emplace_back();
          pending_far.push_back({far_index, static_cast<int>(q)});
        }
        const int first = add_children(c, sd, depth, bnd, bnd1, fi, far_index);
        tree[id].first_child = first;
      }
    }
    // The new far fields (each from its node's values and its parent's far field), in parallel.
    const long np = static_cast<long>(pending_far.size());
#pragma omp parallel for schedule(dynamic, 4) if (np > 1)
    for (long k = 0; k < np; ++k) {
      const int q = pending_far[k].second;
      const Node& nd = tree[batch[q]];
      const FarField* parent = nd.far >= 0 ? &far[nd.far] : nullptr;
      build_far(far[pending_far[k].first], nd.c, 0.5 * std::sqrt(3.0) * nd.side, vals[q], batch_jets[q],
                parent, nullptr);
    }
    pending_far.clear();
  }
  std::vector<std::pair<int, int>> pending_far;  // (index into far, position in the batch)

  // The 8 children of each leaf leaves[i], i in `split` (octant order, child k of split[j] at tree[8 j + k]),
  // evaluated as refinement nodes with their own bound only; counted against the refinement budget. The
  // tightening and the distortion stages refine leaves this way.
  void evaluate_children(const std::vector<CertLeaf>& leaves, const std::vector<size_t>& split,
                         std::vector<int>& batch, std::vector<NodeValues>& vals) {
    tree.clear();
    batch.clear();
    for (size_t i : split) {
      const CertLeaf& l = leaves[i];
      for (int k = 0; k < 8; ++k) {
        const Vec3 off((k & 1 ? 0.25 : -0.25), (k & 2 ? 0.25 : -0.25), (k & 4 ? 0.25 : -0.25));
        batch.push_back(static_cast<int>(tree.size()));
        tree.push_back({l.center + l.side * off, l.side / 2, l.depth + 1, kInf, kInf, 0, -1, {}});
      }
    }
    budget_used += static_cast<long>(batch.size());
    evaluate_batch(batch, vals);
  }

  // --- 5. Assemble, in base-voxel order with each subtree depth-first (children in octant order).
  Certificate assemble() {
    bool all_ok = true;
    cert.min_margin = kInf;
    cert.min_lower_bound = kInf;
    long leaves = 0;
    cert.base_lower.assign(N, kInf);
    cert.base_upper.assign(N, 0.0);
    cert.max_sigma1_upper_bound = 0;
    cert.max_distortion_upper_bound = 0;
    auto emit = [&](const CertLeaf& l) {
      ++leaves;
      if (l.base >= 0 && l.base < N) {
        cert.base_lower[l.base] = std::min(cert.base_lower[l.base], l.margin);
        cert.base_upper[l.base] = std::max(cert.base_upper[l.base], l.sigma1_upper);
      }
      cert.max_sigma1_upper_bound = std::max(cert.max_sigma1_upper_bound, l.sigma1_upper);
      cert.max_distortion_upper_bound = std::max(cert.max_distortion_upper_bound, l.distortion_upper);
      cert.min_margin = std::min(cert.min_margin, l.margin);
      // σ3 − r L − τ: the rounding allowance τ belongs to the bound (σ3 and L are computed in floating
      // point), so this is a lower bound of the true σ3 on the leaf; a leaf left unevaluated counts as −∞.
      cert.min_lower_bound = std::min(cert.min_lower_bound, l.margin);
      if (!l.certified) {
        all_ok = false;
        if (l.sign_unresolved)
          ++cert.sign_unresolved_leaves;
        else if (l.sigma3 <= 0)
          resolved_nonpositive = true;
        if (static_cast<int>(cert.failing.size()) < p.max_failing_reported) cert.failing.push_back(l);
      }
      // tighten() and enforce_distortion() need them
      if (p.keep_leaves || p.bound_tolerance > 0 || p.targets().any()) cert.leaves.push_back(l);
    };
    std::vector<int> stack;
    size_t fi = 0;
    for (long i = 0; i < N; ++i) {
      const bool refined_here = fi < failing_base.size() && failing_base[fi] == i;
      if (!refined_here || vs[fi].first_child < 0) {
        emit(base[i]);
        if (refined_here) {
          all_ok = false;
          ++fi;
        }
        continue;
      }
      const VoxelState& st = vs[fi];
      all_ok = all_ok && st.ok;
      cert.refined += st.refined;
      cert.max_depth_used = std::max(cert.max_depth_used, st.depth_used);
      cert.min_sigma3_center = std::min(cert.min_sigma3_center, st.min_sigma);
      stack.clear();
      for (int k = 7; k >= 0; --k) stack.push_back(st.first_child + k);
      while (!stack.empty()) {
        const Node& nd = tree[stack.back()];
        stack.pop_back();
        if (nd.first_child >= 0) {
          for (int k = 7; k >= 0; --k) stack.push_back(nd.first_child + k);
        } else {
          emit(nd.leaf);
        }
      }
      ++fi;
    }
    cert.certified = all_ok;
    cert.num_leaves = leaves;
    if (!cert.certified) {
      cert.base_lower.clear();
      cert.base_upper.clear();
    }
    cert.perturbed_voxels = perturbed.empty() ? 0 : std::count(perturbed.begin(), perturbed.end(), 1);
    for (size_t k = 0; k < vs.size() && cert.failed_voxels.size() < 64; ++k)
      if (vs[k].failed_here) cert.failed_voxels.push_back(failing_base[k]);
    cert.uncleared_voxels = static_cast<long>(uncleared.size());
    if (!cert.certified) cert.reason = failure_reason();
    return std::move(cert);
  }
  // --- 6. Tightening (CertifyParams::bound_tolerance), only once the map is certified, so it never changes
  // the verdict. Each round splits the leaves whose margin is below (1 − tol) · the smallest sampled σ3
  // into 8 children evaluated like refinement nodes (their own bound only). A leaf is replaced by its
  // children only when every child's margin exceeds the leaf's: both are valid lower bounds of σ3 on the
  // same voxel (the children tile it), so the larger is kept; the leaves still tile the base voxels. The
  // children's σ3 are sampled values of σ3 and lower min_sigma3_center with them.
  void tighten(Certificate& c) {
    c.bound_tolerance = p.bound_tolerance;
    if (p.bound_tolerance <= 0 || !c.certified) return;
    const auto t0 = Clock::now();
    std::vector<char> settled(c.leaves.size(), 0);
    std::vector<int> batch;
    std::vector<NodeValues> vals;
    for (;;) {
      const double target = (1 - p.bound_tolerance) * c.min_sigma3_center;
      std::vector<size_t> split;
      for (size_t i = 0; i < c.leaves.size(); ++i)
        if (!settled[i] && c.leaves[i].margin < target && c.leaves[i].depth < p.max_depth &&
            budget_used + 8 * static_cast<long>(split.size() + 1) <= p.max_refined_voxels)
          split.push_back(i);
      if (split.empty()) break;
      evaluate_children(c.leaves, split, batch, vals);
      std::vector<CertLeaf> next;
      std::vector<char> next_settled;
      next.reserve(c.leaves.size() + 7 * split.size());
      size_t si = 0;
      for (size_t i = 0; i < c.leaves.size(); ++i) {
        const CertLeaf& l = c.leaves[i];
        if (si >= split.size() || split[si] != i) {
          next.push_back(l);
          next_settled.push_back(settled[i]);
          continue;
        }
        CertLeaf kids[8];
        double worst = kInf;
        for (int k = 0; k < 8; ++k) {
          kids[k] = child_leaf(tree[8 * si + k], vals[8 * si + k], l.base);
          const NodeValues& v = vals[8 * si + k];
          const double margin = kids[k].margin;
          worst = std::min(worst, margin);
          c.min_sigma3_center = std::min(c.min_sigma3_center, v.sigma3);
        }
        ++si;
        if (worst > l.margin) {
          ++c.refined;
          for (const CertLeaf& kid : kids) {
            next.push_back(kid);
            next_settled.push_back(0);
          }
        } else {
          next.push_back(l);  // its own bound is the better one: keep it, and stop splitting it
          next_settled.push_back(1);
        }
      }
      c.leaves.swap(next);
      settled.swap(next_settled);
    }
    summarize_leaves(c);
    c.num_leaves = static_cast<long>(c.leaves.size());
    c.bound_tolerance_met = c.min_lower_bound >= (1 - p.bound_tolerance) * c.min_sigma3_center;
    c.ms_refine += ms_since(t0);
  }
  // A leaf from a node evaluated exactly with its own bound only (the tightening and distortion stages).
  CertLeaf child_leaf(const Node& nd, const NodeValues& v, int base_index) const {
    const double rad = 0.5 * std::sqrt(3.0) * nd.side;
    const double L = lipschitz(v.hnorm, v.hnorm_op, combined ? v.own_first : v.own_bound, v.own_bound, rad);
    const double margin = node_margin(v, 0.0, L, rad);
    CertLeaf leaf{nd.c, nd.side, nd.depth, v.sigma3, L, margin, margin > 0, base_index, v.sign_unresolved};
    const double L1 =
        lipschitz(v.hnorm, v.hnorm_op_j, combined ? v.own_first : v.own_bound, v.own_bound, rad);
    set_distortion(leaf, v.sigma1, 0.0, L1, rad, v.scale_J, v.scale_H, 0.0, &v.taylor, v.own_bound);
    return leaf;
  }

  // --- 7. Bounded distortion (CertifyParams::max_distortion, max_sigma1, min_sigma3; docs/certificate.md,
  // "Bounded distortion"), only once the map is certified. Each round splits the leaves whose bounds do not
  // prove a target into 8 children evaluated like the tightening stage's. A leaf is replaced by its children
  // only when all are certified and their largest excess (DistortionTargets::excess) is below the leaf's
  // (both are valid bounds on the same voxel); the leaves still tile the base voxels. A target still unproven
  // when depth or budget runs out makes the map not certified, naming the leaf.
  // The center values' excess (σ1/σ3 over K, σ1 over S, s over σ3) above which the line search's distortion
  // stage refines a leaf in its first phase: within 0.5% of a target, where proofs are deepest and fail.
  static constexpr double kCriticalExcess = 0.995;
  void enforce_distortion(Certificate& c) {
    set_targets(c);
    c.distortion_met = false;
    if (!targets.any() || !c.certified) return;
    const auto t0 = Clock::now();
    std::vector<char> settled(c.leaves.size(), 0);
    std::vector<int> batch;
    std::vector<NodeValues> vals;
    // In a line search (stop_on_failure) the base voxels most likely to fail are refined first, to
    // completion: the priority voxels and those of the distortion probes (where earlier trials failed) and
    // those with a leaf whose center is within kCriticalExcess of a target. A trial that cannot prove a
    // target there is refused before the rest is refined. Each leaf's refinement depends on its own values
    // only, so the verdict and, when the map is certified, the leaves are those of one pass over all leaves
    // (the budget, counted in both, runs out in both alike).
    std::vector<long> prio;
    if (p.stop_on_failure) {
      prio = p.priority_voxels;
      for (long i : probe_voxels())
        if (i >= 0) prio.push_back(i);
      for (const CertLeaf& l : c.leaves)
        if (l.sigma3 > 0 && targets.excess(l.sigma1, l.sigma3, l.sigma1 / l.sigma3) > kCriticalExcess)
          prio.push_back(l.base);
    }
    std::sort(prio.begin(), prio.end());
    // Per base voxel, so that a leaf's children stay in its phase.
    auto in_phase = [&](const CertLeaf& l, bool first) {
      return !first || std::binary_search(prio.begin(), prio.end(), static_cast<long>(l.base));
    };
    // A leaf that does not prove a target and cannot be split (settled, its center already beyond a target,
    // or at the depth limit); the budget is checked apart.
    auto splittable = [&](const CertLeaf& l, char leaf_settled) {
      // A target violated at the center itself beyond the float storage allowance (sigma3_error, which
      // bounds both singular values' error by Weyl) and rounding: no child's bounds can prove it, as each
      // child's ball contains the center. Not split; a line search trial fails here.
      const double e = std::isfinite(l.sigma3_error) ? l.sigma3_error : kInf;
      const bool center_violates =
          targets.violated(l.sigma1 - e, l.sigma3 + e, 1e-9) != DistortionTarget::kNone;
      return !leaf_settled && !center_violates && l.depth - level(l.base) < p.max_depth;
    };
    bool hopeless = false, first_phase = p.stop_on_failure;
    // Why leaves stayed unproven: one that could be split was not (the budget ran out), or one could not be
    // split (depth limit, a center beyond a target, children no better).
    bool budget_out = false, stuck = false;
    // A leaf that fails at once fails the trial before any phase (as the first round of one pass would).
    for (size_t i = 0; i < c.leaves.size() && first_phase; ++i)
      if (unproven(c.leaves[i]) != DistortionTarget::kNone && !splittable(c.leaves[i], settled[i]))
        hopeless = stuck = true, first_phase = false;
    for (; !hopeless;) {
      std::vector<size_t> split;
      for (size_t i = 0; i < c.leaves.size() && !hopeless; ++i) {
        const CertLeaf& l = c.leaves[i];
        if (unproven(l) == DistortionTarget::kNone || !in_phase(l, first_phase)) continue;
        const bool can_split = splittable(l, settled[i]);
        if (can_split && budget_used + 8 * static_cast<long>(split.size() + 1) <= p.max_refined_voxels) {
          split.push_back(i);
          continue;
        }
        (can_split ? budget_out : stuck) = true;
        hopeless = p.stop_on_failure;  // a line search trial fails here whatever the others give: stop
      }
      if (split.empty() && first_phase && !hopeless) {
        first_phase = false;
        continue;
      }
      if (split.empty() || hopeless) break;
      evaluate_children(c.leaves, split, batch, vals);
      std::vector<CertLeaf> next;
      std::vector<char> next_settled;
      next.reserve(c.leaves.size() + 7 * split.size());
      size_t si = 0;
      for (size_t i = 0; i < c.leaves.size(); ++i) {
        const CertLeaf& l = c.leaves[i];
        if (si >= split.size() || split[si] != i) {
          next.push_back(l);
          next_settled.push_back(settled[i]);
          continue;
        }
        CertLeaf kids[8];
        double worst = 0;
        bool all_certified = true;
        for (int k = 0; k < 8; ++k) {
          kids[k] = child_leaf(tree[8 * si + k], vals[8 * si + k], l.base);
          worst = std::max(worst, excess(kids[k]));
          all_certified = all_certified && kids[k].certified;
          c.min_sigma3_center = std::min(c.min_sigma3_center, kids[k].sigma3);
        }
        ++si;
        if (all_certified && worst < excess(l)) {
          ++c.refined;
          for (const CertLeaf& kid : kids) {
            next.push_back(kid);
            next_settled.push_back(0);
          }
        } else {
          next.push_back(l);
          next_settled.push_back(1);
        }
      }
      c.leaves.swap(next);
      settled.swap(next_settled);
    }
    c.num_leaves = static_cast<long>(c.leaves.size());
    summarize_leaves(c);
    c.distortion_met = true;
    for (const CertLeaf& l : c.leaves) {
      const DistortionTarget which = unproven(l);
      // Refused in the first phase: the other leaves were not refined, so only the priority leaves are named.
      if (which == DistortionTarget::kNone || !in_phase(l, first_phase)) continue;
      if (c.distortion_met) c.distortion_failed_on = which;  // the first failing leaf's: the reason names it
      c.distortion_met = false;
      c.failing.push_back(l);
      if (static_cast<long>(c.failed_voxels.size()) < 64) c.failed_voxels.push_back(l.base);
      if (static_cast<int>(c.failing.size()) >= p.max_failing_reported) break;
    }
    if (!c.distortion_met) {
      std::sort(c.failed_voxels.begin(), c.failed_voxels.end());
      c.failed_voxels.erase(std::unique(c.failed_voxels.begin(), c.failed_voxels.end()),
                            c.failed_voxels.end());
      c.certified = false;
      c.distortion_failed = true;
      c.distortion_budget = budget_out && !stuck ? p.max_refined_voxels : 0;
      c.reason = c.distortion_reason();
      c.base_lower.clear();
      c.base_upper.clear();
    }
    c.ms_refine += ms_since(t0);
  }
  // The per-leaf summaries (bounds, per base voxel bounds, depth) from the leaves after a stage changed them.
  void summarize_leaves(Certificate& c) const {
    c.min_margin = kInf;
    c.max_sigma1_upper_bound = 0;
    c.max_distortion_upper_bound = 0;
    if (c.certified) {
      c.base_lower.assign(N, kInf);
      c.base_upper.assign(N, 0.0);
    }
    for (const CertLeaf& l : c.leaves) {
      c.min_margin = std::min(c.min_margin, l.margin);
      c.max_depth_used = std::max(c.max_depth_used, l.depth);
      c.max_sigma1_upper_bound = std::max(c.max_sigma1_upper_bound, l.sigma1_upper);
      c.max_distortion_upper_bound = std::max(c.max_distortion_upper_bound, l.distortion_upper);
      if (c.certified && l.base >= 0 && l.base < N) {
        c.base_lower[l.base] = std::min(c.base_lower[l.base], l.margin);
        c.base_upper[l.base] = std::max(c.base_upper[l.base], l.sigma1_upper);
      }
    }
    c.min_lower_bound = c.min_margin;
  }

  // A resolved σ3 ≤ 0 at an evaluated center (every such center is a leaf): the map folds there.
  bool resolved_nonpositive = false;
  std::string failure_reason() const {
    if (!uncleared.empty()) {
      const long i = uncleared.front();
      const Vec3 c = oc.sampling_.centers.row(i);
      return std::to_string(uncleared.size()) + " voxel(s) not clear of the cage, never certified (first: #" +
             std::to_string(i) + " at (" + std::to_string(c.x()) + ", " + std::to_string(c.y()) + ", " +
             std::to_string(c.z()) + "), radius " +
             std::to_string(oc.sampling_.radius_of(static_cast<int>(i))) +
             "): the domain touches or crosses the cage there";
    }
    if (resolved_nonpositive)
      return "sigma3 <= 0 at a sampled center: the map is not locally injective there";
    if (cert.sign_unresolved_leaves > 0)
      return "could not prove sigma3 > 0 within rounding (" + std::to_string(cert.sign_unresolved_leaves) +
             " leaves where det J's sign is not resolved in double precision)";
    if (budget_hit)
      return "refinement budget exhausted (" + std::to_string(p.max_children_per_voxel) + " per voxel, " +
             std::to_string(p.max_refined_voxels) + " in all)";
    if (p.stop_on_failure && abort) return "a voxel failed at maximum depth " + std::to_string(p.max_depth);
    return "condition (6) fails on " + std::to_string(cert.failing.size()) +
           (cert.failing.size() == static_cast<size_t>(p.max_failing_reported) ? "+" : "") +
           " leaf voxel(s) at maximum depth " + std::to_string(p.max_depth);
  }
};

bool OctreeCertifier::distortion_refuted(const Eigen::Matrix<double, Eigen::Dynamic, 3>& yr,
                                         const CertifyParams& params, Certificate& refusal,
                                         bool search) const {
  const auto t_start = Clock::now();
  if (!params.stop_on_failure || !params.targets().any() || params.distortion_probes.empty()) return false;
  const MatX3d y = expand_reduced(yr, "distortion_refuted");
  Run run(*this, y, yr.data(), yr.rows(), params);
  Certificate out;
  if (!run.distortion_probe(out, search)) return false;
  out.ms_total = ms_since(t_start);
  refusal = std::move(out);
  return true;
}

Certificate OctreeCertifier::run(const MatX3d& y, const double* yr_ptr, long yr_rows,
                                 const CertifyParams& p) const {
  const auto t_start = Clock::now();
  if (p.max_depth < 0) throw InputError("", "max depth must be >= 0");
  Run run(*this, y, yr_ptr, yr_rows, p);
  if (Certificate quick; run.distortion_probe(quick)) {
    quick.ms_total = ms_since(t_start);
    return quick;
  }
  run.perturbation();
  run.list_evaluated();
  run.base_derivatives();
  run.base_sigma3();
  run.base_bounds();
  run.refine();
  Certificate cert = run.assemble();
  run.tighten(cert);
  run.enforce_distortion(cert);
  if (!p.keep_leaves) cert.leaves.clear();  // kept only for the stages above
  cert.ms_total = ms_since(t_start);
  return cert;
}

const char* to_string(RefinementEval r) {
  return enum_name(r);
}

Certificate certify_map(const Cage& cage, const VoxelSampling& sampling, const MatX3d& y,
                        const CertifyParams& params) {
  return OctreeCertifier(cage, sampling).certify(y, params);
}

}  // namespace lidef
