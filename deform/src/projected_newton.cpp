#include "lidef/projected_newton.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>

#include "lidef/blas_kernel.h"
#include "lidef/domain_sampling.h"
#include "lidef/errors.h"
#include "lidef/internal/cholesky.h"
#include "lidef/internal/distortion_screen.h"
#include "lidef/internal/enum_names.h"
#include "lidef/internal/newton_cg.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/number_format.h"

namespace lidef {

namespace {

// The distortion Hessian kept for the current map in both forms (DeformationSolver::hessian_blocks_ and
// subset_blocks_), forgotten together wherever the kernels' map changes.
void forget_map_hessian(MatXd& pair_blocks, std::vector<Mat9>& subset_blocks) {
  pair_blocks = MatXd();
  subset_blocks.clear();
}

bool stop_requested(const std::atomic<bool>* stop) {
  return stop && stop->load(std::memory_order_relaxed);
}

void check_finite(const MatX3d& P, const std::string& where, const char* what) {
  for (Eigen::Index i = 0; i < P.rows(); ++i)
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(P(i, c)))
        throw InputError(where, "handle " + std::to_string(i + 1) + ": " + what + "[" + std::to_string(c) +
                                    "] is not a finite number");
}

// Points kept for the distortion probes: the failing leaves of about two refused trials
// (CertifyParams::max_failing_reported each); each costs one exact evaluation per trial.
constexpr size_t kMaxDistortionProbes = 40;

}  // namespace

template <>
struct EnumNames<StopReason> {
  static constexpr const char* names[] = {"converged",          "max_iterations", "blocked_by_certificate",
                                          "no_certified_step",  "interrupted",    "reached_not_converged",
                                          "targets_unreachable"};
};

const char* to_string(StopReason r) {
  return enum_name(r);
}

// The stages of the constructor, with progress, cancellation and the precomputation cache around them.
struct DeformationSolver::Precompute {
  DeformationSolver& S;
  const PrecomputeSetup& setup;
  PrecomputeCache cache;
  std::string stage;
  double begin = 0, end = 0;  // fractions of the whole precomputation the current stage spans

  Precompute(DeformationSolver& solver, const PrecomputeSetup& st)
      : S(solver), setup(st), cache(st.cache_dir, st.cache_max_bytes) {}

  void say(const std::string& s) const {
    if (setup.log) setup.log(s);
  }
  // Stage `name` runs from fraction b to e of the whole. The spans are the stage times measured on the
  // animal (docs/benchmarks.md, "Opening a model"), so that the bar moves evenly.
  void enter(const std::string& name, double b, double e) {
    stage = name;
    begin = b;
    end = e;
    tick(0);
  }
  // `f` of the current stage done; throws Cancelled once the caller asked.
  void tick(double f) const {
    if (setup.cancel && setup.cancel->load(std::memory_order_relaxed)) throw Cancelled();
    if (setup.progress) setup.progress(stage, begin + (end - begin) * std::min(1.0, std::max(0.0, f)));
  }

  // Everything the sampling, the gradients and the certifier's derivatives depend on.
  bool mesh_domain() const { return setup.mesh && S.params_.domain == DomainKind::kMesh; }

  CacheKey key() const {
    CacheKey k("solver");
    k.add_matrix(S.cage_.V).add_matrix(S.cage_.F);
    const SamplingParams sp = S.sampling_params();
    k.add(sp.target_count).add(sp.count_tolerance).add(sp.voxel_side).add(sp.safety);
    k.add(sp.hessian_fraction).add(sp.max_search_iterations);
    // The domain: the grid, or the mesh's triangles and solid (its exact bytes and the refinement limits).
    k.add(std::string(mesh_domain() ? "mesh" : "voxels"));
    if (mesh_domain()) {
      k.add_matrix(setup.mesh->V).add_matrix(setup.mesh->F);
      k.add(sp.max_domain_level).add(sp.max_leaves_per_cell);
    }
    k.add_matrix(S.subspace_.basis).add_matrix(S.subspace_.eigenvalues);
    return k.add_numerics();
  }

  void subspace() {
    enter("subspace", 0.0, 0.02);
    const auto t0 = Clock::now();
    // Keyed by the normalized cage's exact vertex bytes: a translated or scaled copy that normalizes to other
    // bytes gets its own entry, one that normalizes to the same bytes (a power-of-two scaling) shares it, and
    // rightly so, since the subspace is computed from those bytes alone.
    S.subspace_ = load_or_compute_subspace(S.ncage_, S.params_.reduced_dof, setup.cache_dir);
    say("subspace: " + std::to_string(S.subspace_.size()) + " of " + std::to_string(S.ncage_.num_coeffs()) +
        " coefficients per coordinate (" + S.subspace_.solver + ", " + format_g(ms_since(t0), 4) + " ms)");
  }

  void sampling() {
    enter("sampling", 0.02, 0.04);
    const auto t0 = Clock::now();
    // Laid out in frame_ (sampling.h, domain_sampling.h).
    S.sampling_ = mesh_domain() ? sample_domain(S.cage_, setup.mesh->V, setup.mesh->F, S.sampling_params())
                                : sample_voxels(S.cage_, S.sampling_params());
    S.nsampling_ = S.frame_.to_normalized(S.sampling_);
    if (S.sampling_.size() == 0)
      throw InputError(S.cage_.source,
                       "no voxel of side " + format_g(S.sampling_.side, 4) +
                           " fits inside the cage (use a smaller voxel_side or more samples)");
    say("sampling (" + S.sampling_.domain + " domain): " + std::to_string(S.sampling_.size()) +
        " voxels of side " + format_g(S.sampling_.side, 4) +
        (S.sampling_.max_level() > 0 ? " refined to level " + std::to_string(S.sampling_.max_level())
                                     : std::string()) +
        ", " + std::to_string(S.sampling_.hessian_subset.size()) + " in the Hessian subset (" +
        format_g(ms_since(t0), 4) + " ms)");
  }

  void certifier() {
    enter("basis derivatives at the samples", 0.04, 0.85);
    const auto t0 = Clock::now();
    S.certifier_ = std::make_unique<OctreeCertifier>(S.ncage_, S.nsampling_, &S.subspace_.basis, 1.5e9,
                                                     [this](double f) { tick(f); });
    S.perturb_lower_.clear();  // bounds of another certifier's voxels
    S.perturb_upper_.clear();
    say("certificate precomputation (basis gradients and Hessians at the samples): " +
        format_g(ms_since(t0), 4) + " ms");
  }

  // The reduced gradient matrix G = (∇basis at the centers) Ξ (3|I| by s) of the energy, from the certifier's
  // gradient rows: the energy keeps G in float (deformation_energy.h), and float(∇basis Ξ) is exactly what
  // the certifier stores, so the basis is evaluated once for both.
  MatXdR gradients() const {
    const OctreeCertifier::ReducedDerivativesRef d = S.certifier_->reduced_derivatives();
    const long n = S.nsampling_.size(), m = d.m;
    MatXdR G(3 * n, m);
#pragma omp parallel for schedule(static)
    for (long i = 0; i < n; ++i)
      for (long r = 0; r < 3; ++r)
        for (long k = 0; k < m; ++k) G(3 * i + r, k) = (*d.GH)[static_cast<size_t>((9 * i + r) * m + k)];
    return G;
  }

  // The sampling and the certifier (its derivatives and, when the entry has them, its third-order bound
  // factors) from the cache; false (nothing changed) when it has no valid entry.
  bool load(const CacheKey& k) {
    enter("reading the cache", 0.02, 0.5);
    std::vector<char> payload;
    CacheEvent ev;
    if (!cache.load(k, payload, &ev)) {
      S.cache_outcome_ = ev.outcome;
      if (cache.enabled()) say("precomputation " + describe(ev));
      return false;
    }
    tick(0.7);
    try {
      CacheReader r(std::move(payload));
      VoxelSampling vs = read_sampling(r);
      const long n = vs.size();
      OctreeCertifier::ReducedDerivatives d;
      d.GH = r.array<float>();
      d.m = r.scalar<long>();
      r.matrix(d.scale_J, n, 1);
      r.matrix(d.scale_H, n, 1);
      OctreeCertifier::FactorMatrix third, first;  // none (0 rows) when the storing run had not built them
      r.matrix(third);
      std::vector<char> third_finite = r.array<char>();
      r.matrix(first);
      std::vector<char> first_finite = r.array<char>();
      OctreeCertifier::PerturbationConstants pert;  // none (0 rows) when the storing run had not built them
      r.matrix(pert.g2);
      r.matrix(pert.rest);
      r.matrix(pert.gF);
      MatXd rest;
      r.matrix(rest);
      if (!r.at_end() || n == 0) throw CacheReader::Bad{};
      const long s = S.subspace_.size();
      if (rest.size() > 0 && (rest.rows() != s || rest.cols() != 6 * s)) throw CacheReader::Bad{};
      S.rest_hessian_blocks_ = std::move(rest);
      S.sampling_ = std::move(vs);
      S.nsampling_ = S.frame_.to_normalized(S.sampling_);
      S.certifier_ =
          std::make_unique<OctreeCertifier>(S.ncage_, S.nsampling_, &S.subspace_.basis, std::move(d));
      if (third.size() > 0) S.certifier_->adopt_factors(true, std::move(third), std::move(third_finite));
      if (first.size() > 0) S.certifier_->adopt_factors(false, std::move(first), std::move(first_finite));
      if (pert.g2.size() > 0) S.certifier_->adopt_perturbation_constants(std::move(pert));
      S.perturb_lower_.clear();  // bounds of another certifier's voxels
      S.perturb_upper_.clear();
    } catch (const CacheReader::Bad&) {
      return rejected(k, "malformed payload");
    } catch (const Error& e) {
      return rejected(k, e.what());
    }
    S.cache_outcome_ = "hit";
    say("precomputation (sampling, certificate derivatives, bound factors and perturbation constants) " +
        describe(ev));
    return true;
  }
  bool rejected(const CacheKey& k, const std::string& why) {
    S.certifier_.reset();
    std::error_code ec;
    std::filesystem::remove(cache.path(k), ec);
    S.cache_outcome_ = "rebuilt (" + why + ")";
    say("precomputation cache: " + S.cache_outcome_);
    return false;
  }

  // After the identity's certificate, which built the third-order bound factors (unless the bound is the
  // first-order one: then the entry has none).
  void store(const CacheKey& k) {
    if (!cache.enabled()) return;
    const CacheEvent ev = store_entry(cache, k, S.sampling_, *S.certifier_, S.rest_hessian_blocks_);
    say("precomputation " + describe(ev) + "; " + describe(cache.usage()));
  }
  static CacheEvent store_entry(const PrecomputeCache& cache, const CacheKey& k,
                                const VoxelSampling& sampling, const OctreeCertifier& certifier,
                                const MatXd& rest_hessian_blocks) {
    const auto d = certifier.reduced_derivatives();
    const OctreeCertifier::FactorMatrix none;  // the writer keeps pointers: these outlive it
    const std::vector<char> no_finite;
    CacheWriter w;
    write_sampling(w, sampling);
    w.array(d.GH->data(), d.GH->size());
    w.scalar(d.m);
    w.matrix(*d.scale_J);
    w.matrix(*d.scale_H);
    for (const bool third_kind : {true, false}) {  // each bound's factors, or an empty matrix and array
      const std::vector<char>* finite = nullptr;
      const OctreeCertifier::FactorMatrix* factors = certifier.built_factors(third_kind, &finite);
      w.matrix(factors ? *factors : none);
      const std::vector<char>& f = factors ? *finite : no_finite;
      w.array(f.data(), f.size());
    }
    const OctreeCertifier::PerturbationConstants* pert = certifier.perturbation_constants_if_built();
    const VecXd none_built;
    w.matrix(pert ? pert->g2 : none_built);
    w.matrix(pert ? pert->rest : none_built);
    w.matrix(pert ? pert->gF : none_built);
    w.matrix(rest_hessian_blocks);
    CacheEvent ev;
    cache.store(k, w, &ev);
    return ev;
  }
};

namespace {
PrecomputeSetup setup_of(const std::string& cache_dir, const std::function<void(const std::string&)>& log,
                         const TriMesh* mesh) {
  PrecomputeSetup s;
  s.cache_dir = cache_dir;
  s.log = log;
  s.mesh = mesh;
  return s;
}
}  // namespace

DeformationSolver::DeformationSolver(const Cage& cage, const DeformParams& params,
                                     const std::string& cache_dir,
                                     const std::function<void(const std::string&)>& log,
                                     std::shared_ptr<const ComputeBackend> backend)
    : DeformationSolver(cage, params, setup_of(cache_dir, log, nullptr), std::move(backend)) {}

DeformationSolver::DeformationSolver(const Cage& cage, const TriMesh& mesh, const DeformParams& params,
                                     const std::string& cache_dir,
                                     const std::function<void(const std::string&)>& log,
                                     std::shared_ptr<const ComputeBackend> backend)
    : DeformationSolver(cage, params, setup_of(cache_dir, log, &mesh), std::move(backend)) {}

DeformationSolver::DeformationSolver(const Cage& cage, const DeformParams& params,
                                     const PrecomputeSetup& setup,
                                     std::shared_ptr<const ComputeBackend> backend)
    : cage_(cage),
      frame_(Frame::of(cage)),
      ncage_(frame_.normalized(cage)),
      params_(params),
      basis_(cage),
      nbasis_(ncage_),
      backend_(backend ? std::move(backend) : cpu_backend()) {
  validate_params(params_, "parameters");
  if (params_.threads > 0) omp_set_num_threads(params_.threads);
  if (setup.mesh) mesh_ = *setup.mesh;
  mesh_domain_ = setup.mesh && params_.domain == DomainKind::kMesh;
  const auto t_all = Clock::now();
  Precompute pc(*this, setup);
  pc.subspace();
  const CacheKey key = pc.key();
  const bool cached = pc.load(key);
  if (!cached) {
    pc.sampling();
    pc.certifier();
  }
  energy_ = std::make_unique<DeformationEnergy>(pc.gradients(), nsampling_.hessian_subset,
                                                subspace_.eigenvalues, ncage_.num_edges());
  if (nsampling_.max_level() > 0) {  // volume weights of the refined leaves (deformation_energy.h)
    VecXd w(nsampling_.size());
    for (int i = 0; i < nsampling_.size(); ++i) w(i) = nsampling_.weight_of(i);
    energy_->set_sample_weights(w);
  }

  pc.enter("certificate of the identity", pc.end, cached || !pc.cache.enabled() ? 1.0 : 0.93);
  auto t0 = Clock::now();
  kernels_ = backend_->energy_kernels(*energy_);
  forget_map_hessian(hessian_blocks_, subset_blocks_);
  certifier_->set_backend(*backend_);
  if (!backend_->is_cpu())
    pc.say("backend " + backend_->name() + ": device buffers " + format_g(ms_since(t0), 4) + " ms");

  bbox_diag2_ = (ncage_.bbox_max - ncage_.bbox_min).squaredNorm();
  t0 = Clock::now();
  reset();
  pc.say("certificate of the identity: " + format_g(ms_since(t0), 4) + " ms");
  rest_y_ = y_;
  if (rest_hessian_blocks_.size() == 0) {
    // The first Newton iteration from rest assembles this (the same bits: CpuEnergyKernels computes the
    // blocks from the same Jacobians); like the constants below it depends on the model alone, so it is built
    // once here and kept in the cache entry. On the host under every backend, so that every entry holds it.
    t0 = Clock::now();
    rest_hessian_blocks_ = energy_->distortion_pair_blocks(energy_->jacobians(y_), false);
    pc.say("the reduced Hessian at rest: " + format_g(ms_since(t0), 4) + " ms");
  }
  if (!certifier_->perturbation_constants_if_built()) {
    // Map-independent (Step 4e): built here rather than in the first line search after an accepted step, and
    // stored in the cache entry. Also under a device backend (whose certificates do not use them), so that
    // every entry holds them for a later CPU solve of the same model.
    t0 = Clock::now();
    certifier_->perturbation_constants();
    pc.say("certificate by perturbation, per-voxel constants: " + format_g(ms_since(t0), 4) + " ms");
  }
  const std::vector<char>* first_finite = nullptr;
  if (certifier_->direction_rest_pays() && !certifier_->built_factors(false, &first_finite)) {
    // The rest from a direction (Step 4e): like the constants above, built once and kept in the cache entry.
    t0 = Clock::now();
    certifier_->factor_matrix(false);
    pc.say("certificate by perturbation, first-order factors: " + format_g(ms_since(t0), 4) + " ms");
  }
  if (!cached && pc.cache.enabled() && !setup.background_store) {
    pc.enter("writing the cache", pc.end, 1.0);
    pc.store(key);
  }
  pc.tick(1);
  preprocess_seconds_ = ms_since(t_all) / 1000;
  if (!cached && pc.cache.enabled() && setup.background_store) {
    // One thread for the checksum too: the caller goes on computing on all cores meanwhile.
    cache_store_ =
        std::async(std::launch::async, [this, key, cache = pc.cache] {
          omp_set_num_threads(1);
          lower_calling_thread_priority();
          return describe(Precompute::store_entry(cache, key, sampling_, *certifier_, rest_hessian_blocks_));
        }).share();
  }
}

DeformationSolver::~DeformationSolver() {
  // The store reads this solver's arrays.
  if (cache_store_.valid()) cache_store_.wait();
}

SamplingParams DeformationSolver::sampling_params() const {
  return sampling_params_of(params_);
}

std::string DeformationSolver::global_problem() const {
  if (mesh_.V.rows() == 0) return "the solver was given no mesh";
  if (!mesh_domain_)
    return "the certified domain is the voxel grid, not the mesh's solid (use the mesh domain)";
  if (mesh_.F.rows() == 0) return "a point cloud has no surface whose image could be checked";
  return "";
}

GlobalInjectivity DeformationSolver::check_global(const MatS3& y) const {
  // Global mode checks a sequence of nearby maps: the checker keeps what no map changes within
  // global_cache_mb and each proven map's margins for the next (docs/certificate.md, Step G6). Local mode
  // checks one map, the result, where keeping either is only cost.
  // The first check also makes the checker (the rest mesh's exact checks, the kept basis data): its time is
  // counted in that check's, so that a report's check time is what the check cost.
  const bool global = params_.injectivity == InjectivityMode::kGlobal;
  double setup_ms = 0;
  if (!global_checker_) {
    const auto t0 = Clock::now();
    global_checker_ = std::make_unique<GlobalInjectivityChecker>(
        cage_, mesh_, global ? params_.global_cache_mb : GlobalInjectivityChecker::kDefaultCacheMB);
    setup_ms = ms_since(t0);
  }
  GlobalInjectivityParams gp;
  gp.reuse_margins = global;
  GlobalInjectivity g = global_checker_->check(
      frame_.coefficients_from_normalized(subspace_.basis * y, cage_.num_vertices()), gp);
  g.ms += setup_ms;
  return g;
}

GlobalInjectivity DeformationSolver::global_injectivity() const {
  if (global_y_.rows() == y_.rows() && global_y_ == y_) return global_verdict_;
  const std::string problem = global_problem();
  global_verdict_ = problem.empty() ? check_global(y_) : global_injectivity_not_decided(problem);
  global_y_ = y_;
  return global_verdict_;
}

std::string DeformationSolver::distortion_note() const {
  if (distortion_rejection_.empty()) return "";
  return "; the distortion bound blocks it (" + certify_params(true, false).targets().describe() +
         ", last rejected trial: " + distortion_rejection_ + ")";
}

CertifyParams DeformationSolver::certify_params(bool stop_on_failure, bool keep_leaves) const {
  return certify_params_of(params_, stop_on_failure, keep_leaves);
}

void DeformationSolver::set_params(const DeformParams& p) {
  validate_params(p, "parameters");
  const bool weights_changed = p.lambda_p2p != params_.lambda_p2p || p.lambda_smooth != params_.lambda_smooth;
  DeformParams q = p;
  // Precomputation-shaping parameters cannot change here.
  q.reduced_dof = params_.reduced_dof;
  q.samples = params_.samples;
  q.voxel_side = params_.voxel_side;
  q.safety = params_.safety;
  q.hessian_fraction = params_.hessian_fraction;
  q.domain = params_.domain;
  // A kept Hessian factor stays valid unless what it was assembled with changed (weights are compared at
  // use).
  if (q.diagonal_shift != params_.diagonal_shift || q.hessian_precision != params_.hessian_precision)
    factor_ = {};
  params_ = q;
  if (weights_changed) {
    weights_ = {params_.lambda_p2p, params_.lambda_smooth};
    weight_resets_ = 0;
  }
}

void DeformationSolver::reset_weights() {
  weights_ = {params_.lambda_p2p, params_.lambda_smooth};
  weight_resets_ = 0;
}

void DeformationSolver::reset() {
  const MatX3d yid = ncage_.identity_coefficients();
  y_ = subspace_.basis.transpose() *
       yid;  // exact: the affine maps lie in span Ξ, whose columns are orthonormal
  kernels_->set_current(y_);
  forget_map_hessian(hessian_blocks_, subset_blocks_);
  factor_ = {};
  weights_ = {params_.lambda_p2p, params_.lambda_smooth};
  weight_resets_ = 0;
  history_.clear();
  Certificate c = certifier_->certify_reduced(y_, certify_params(false, false));
  if (c.certified) {  // the first line search certifies by perturbation from rest (Step 4e)
    perturb_y_ = y_;
    perturb_lower_ = c.base_lower;
    perturb_upper_ = c.base_upper;
  }
  cert_ = frame_.from_normalized(std::move(c));
  if (!cert_.certified)
    throw NumericalError("the identity map is not certified on this sampling (" + cert_.reason +
                         "); the voxels are too close to the cage — raise 'safety' or use smaller voxels");
}

void DeformationSolver::set_initial_map(const MatX3d& y, const std::string& where) {
  if (y.rows() != cage_.num_coeffs())
    throw InputError(where, "has " + std::to_string(y.rows()) + " coefficient rows; this cage needs " +
                                std::to_string(cage_.num_coeffs()) + " (#V+#F)");
  if (!y.allFinite()) throw InputError(where, "contains a non-finite coefficient");
  const MatX3d yn = frame_.coefficients_to_normalized(y, cage_.num_vertices());
  const MatS3 yr = subspace_.basis.transpose() * yn;
  const double norm = yn.norm();
  const double residual = (subspace_.basis * yr - yn).norm() / std::max(norm, 1e-300);
  if (residual > 1e-9)
    throw InputError(where, "is not in the reduced subspace of this cage (" +
                                std::to_string(subspace_.size()) +
                                " coefficients per coordinate; relative residual " + format_g(residual, 4) +
                                "): projecting it would change the map. A coefficients.txt written by "
                                "'lidef deform' with the same reduced_dof is in it.");
  std::string why;
  if (!set_reduced_map(yr, &why))
    throw InputError(where, "the initial map is not certified on this sampling (" + why +
                                "); lidef deform only starts from certified maps");
  weights_ = {params_.lambda_p2p, params_.lambda_smooth};
  weight_resets_ = 0;
  history_.clear();
}

bool DeformationSolver::set_reduced_map(const MatS3& y, std::string* reason) {
  if (y.rows() != subspace_.size() || !y.allFinite()) {
    if (reason) *reason = "not " + std::to_string(subspace_.size()) + " finite reduced coefficient rows";
    return false;
  }
  if (Certificate refusal; distortion_refuted_map(y, refusal)) {
    if (reason) *reason = refusal.reason;
    return false;
  }
  const Certificate c = certifier_->certify_reduced(y, certify_params(false, false));
  if (!c.certified) {
    if (reason) *reason = c.reason;
    return false;
  }
  if (params_.injectivity == InjectivityMode::kGlobal) {  // every current map of global mode is proven so
    const std::string problem = global_problem();
    const GlobalInjectivity g = problem.empty() ? check_global(y) : global_injectivity_not_decided(problem);
    if (g.verdict != GlobalInjectivity::Verdict::kInjective) {
      if (reason) *reason = "not proven globally injective: " + g.reason;
      return false;
    }
    global_y_ = y;
    global_verdict_ = g;
  }
  y_ = y;
  kernels_->set_current(y_);
  forget_map_hessian(hessian_blocks_, subset_blocks_);
  factor_ = {};  // the map jumped
  cert_ = frame_.from_normalized(c);
  return true;
}

bool DeformationSolver::distortion_refuted_map(const MatS3& y, Certificate& refusal) const {
  // A map beyond a distortion target at some point of the domain is refused by that point's proof alone —
  // the verdict every certificate of it reaches (docs/certificate.md, "Probes") — without its voxels: the
  // continuation's local/global maps and their blends under a binding target took a full certificate each
  // (0.16–1.1 s each on the animal). The probes: the map's sample farthest beyond the targets, then the
  // points where the last line search's trials failed, and where none proves a violation but the worst comes
  // near a target, the search near it (a local/global map, which knows no target, often exceeds one between
  // the samples). Finding no proof decides nothing (the full certificate follows).
  CertifyParams cp = certify_params(true, false);
  const DistortionTargets targets = cp.targets();
  if (!targets.any()) return false;
  const MatJT J = energy_->jacobians(y);
  double excess = 0;
  const long i = largest_excess_sample(J, J, 0.0, targets, &excess);
  cp.distortion_probes.clear();
  if (i >= 0) cp.distortion_probes.push_back(nsampling_.centers.row(i).transpose());
  for (const Vec3& q : distortion_probes_)
    if (cp.distortion_probes.size() < kMaxDistortionProbes) cp.distortion_probes.push_back(q);
  return !cp.distortion_probes.empty() && certifier_->distortion_refuted(y, cp, refusal, /*search=*/true);
}

std::string handle_source_problem(const Cage& cage, const Vec3& p) {
  std::ostringstream pos;
  pos.precision(9);
  pos << "(" << p.x() << ", " << p.y() << ", " << p.z() << ")";
  if (!p.allFinite()) return pos.str() + " is not finite";
  const double w = cage.winding_number(p);
  if (!(w > 0.5)) return pos.str() + " is outside the cage (winding number " + format_g(w, 4) + ")";
  if (cage.distance(p) < 1e-9 * (cage.bbox_max - cage.bbox_min).norm())
    return pos.str() + " lies on the cage, where the harmonic map is undefined";
  return "";
}

void DeformationSolver::set_handles(const MatX3d& sources, const MatX3d& targets, const std::string& where) {
  if (sources.rows() == 0) throw InputError(where, "no handles: at least one handle is needed");
  if (sources.rows() != targets.rows()) throw InputError(where, "as many targets as sources are needed");
  check_finite(sources, where, "source");
  for (Eigen::Index i = 0; i < sources.rows(); ++i) {
    const std::string why = handle_source_problem(cage_, sources.row(i).transpose());
    if (!why.empty()) throw InputError(where, "handle " + std::to_string(i + 1) + ": source " + why);
  }
  const MatX3d previous = sources_;
  sources_ = sources;
  try {
    check_targets(targets, where);
  } catch (...) {
    sources_ = previous;
    throw;
  }
  const MatXd D = nbasis_.value_matrix(frame_.points_to_normalized(sources)) * subspace_.basis;
  energy_->set_handles(D, frame_.points_to_normalized(targets));
  factor_ = {};  // the handle term's Hessian depends on the sources
  ++targets_version_;
}

// Targets that no map can meet sensibly are refused with a reason instead of being run: a target so far away
// that the handle energy overflows, and two handles at one source pulled to different places.
void DeformationSolver::check_targets(const MatX3d& targets, const std::string& where) const {
  check_finite(targets, where, "target");
  const Vec3 center = 0.5 * (cage_.bbox_min + cage_.bbox_max);
  const double diag = (cage_.bbox_max - cage_.bbox_min).norm();
  // 1e6 cage diagonals: far beyond any deformation the certificate could follow, far below overflow of the
  // squared distances in E_P2P (1e300 squared is not a double).
  constexpr double kMaxDiagonals = 1e6;
  for (Eigen::Index i = 0; i < targets.rows(); ++i) {
    // stableNorm: a target at 1e300 would make the plain norm overflow to inf in the message.
    const double d = (targets.row(i).transpose() - center).stableNorm();
    if (!(d <= kMaxDiagonals * diag))
      throw InputError(where, "handle " + std::to_string(i + 1) + ": target is " + format_g(d / diag, 3) +
                                  " cage diagonals from the cage (at most " + format_g(kMaxDiagonals, 1) +
                                  ")");
  }
  // One source, two targets: the handle energy could only average them, which nobody asked for.
  const double same = 1e-12 * diag;
  for (Eigen::Index i = 0; i < sources_.rows(); ++i)
    for (Eigen::Index j = i + 1; j < sources_.rows(); ++j)
      if ((sources_.row(i) - sources_.row(j)).norm() <= same &&
          (targets.row(i) - targets.row(j)).norm() > same)
        throw InputError(where, "handles " + std::to_string(i + 1) + " and " + std::to_string(j + 1) +
                                    " have the same source but different targets");
}

void DeformationSolver::set_targets(const MatX3d& targets, const std::string& where) {
  if (targets.rows() != energy_->num_handles()) throw InputError(where, "one target per handle is needed");
  check_targets(targets, where);
  energy_->set_targets(frame_.points_to_normalized(targets));
  ++targets_version_;  // (the Hessian does not depend on the targets: a kept factor stays valid)
}

MatX3d DeformationSolver::coefficients() const {
  return frame_.coefficients_from_normalized(subspace_.basis * y_, cage_.num_vertices());
}

Certificate DeformationSolver::certify_current(bool keep_leaves) const {
  CertifyParams cp = certify_params(false, keep_leaves);
  Certificate c = certifier_->certify_reduced(y_, cp);
  // The line search may have accepted this map with the spectral fallback (Step 4f) where the third-order
  // bound alone runs out of depth or budget: then the certificate is the fallback's, which proves it too.
  if (!c.certified && params_.line_search_spectral_fallback) {
    cp.base_spectral_fallback = true;
    Certificate f = certifier_->certify_reduced(y_, cp);
    if (f.certified) c = std::move(f);
  }
  return frame_.from_normalized(std::move(c));
}

EnergyTerms DeformationSolver::energy() const {
  return energy_->terms(kernels_->distortion_sum(0), y_, weights_);
}
VecXd DeformationSolver::handle_errors() const {
  return frame_.length_from_normalized(1) * energy_->handle_errors(y_);
}
MatX3d DeformationSolver::handle_positions() const {
  return frame_.points_from_normalized(energy_->handle_positions(y_));
}

// One Newton iteration, as its named stages: the direction (newton_direction), the certified line search
// along it (certified_line_search: each trial's energy, certificate and, in global mode, global injectivity),
// and with dynamic weighting the direction recomputed with weaker handles (weaken_handles) when its full step
// fails the certificate while the handles are still far.
IterationRecord DeformationSolver::step(const std::atomic<bool>* stop) {
  const auto t_iter = Clock::now();
  IterationRecord rec;
  rec.iteration = static_cast<int>(history_.size()) + 1;

  // With dynamic weighting, a direction whose full step fails the certificate while the handles are still far
  // (E_P2P >= E0) is recomputed with weaker handles and more smoothness before the step is shortened: this
  // keeps the path inside the certified region (paper Sec. 7.3, Fig. 9) instead of creeping along its
  // boundary.
  const double p2p_far = params_.e0 * bbox_diag2_;
  const EnergyWeights weights_at_start = weights_;  // restored if the iteration is interrupted
  const int max_attempts = params_.dynamic_weighting ? 1 + params_.direction_retries : 1;
  // Dragging: the first step after new targets may reuse the previous step's factor (set_dragging).
  bool may_reuse =
      dragging_ && params_.drag_hessian_reuse > 0 && targets_version_ != stepped_targets_version_;
  stepped_targets_version_ = targets_version_;
  if (params_.injectivity == InjectivityMode::kGlobal) require_globally_injective_start();
  global_rejection_.clear();
  bool interrupted = false;
  for (int attempt = 0; attempt < max_attempts && !interrupted; ++attempt) {
    rec.lambda_p2p = weights_.p2p;
    rec.lambda_smooth = weights_.smooth;
    rec.armijo_rejections = rec.certificate_rejections = rec.global_rejections = 0;
    distortion_rejection_.clear();
    const bool reuse = may_reuse && factor_.L.size() > 0 && factor_.reuses < params_.drag_hessian_reuse &&
                       factor_.weights.p2p == weights_.p2p && factor_.weights.smooth == weights_.smooth;
    rec.hessian_reused = reuse;
    const NewtonDirection d = newton_direction(reuse, rec);
    const bool may_retry = attempt + 1 < max_attempts && d.e0.p2p >= p2p_far &&
                           (weights_.p2p > params_.min_p2p_factor * params_.lambda_p2p ||
                            weights_.smooth < params_.max_smooth_factor * params_.lambda_smooth);
    const LineSearchEnd end = certified_line_search(d, may_retry, rec, stop);
    interrupted = end == LineSearchEnd::kInterrupted;
    const bool retry = end == LineSearchEnd::kRetry;
    if (rec.hessian_reused && !rec.accepted && !retry && !interrupted) {
      // A kept factor's direction (as it is, or the CG steps' solution) found no certified decrease: this
      // iteration assembles its own, so that "no certified step" and "blocked" mean what they always meant.
      may_reuse = false;
      factor_ = {};
      --attempt;
      continue;
    }
    if (!retry) break;
    weaken_handles(rec);
  }
  finish_record(rec, interrupted, weights_at_start);
  rec.ms_total = ms_since(t_iter);
  history_.push_back(rec);
  return rec;
}

void DeformationSolver::require_globally_injective_start() {
  // Each accepted step keeps global injectivity only if the map it starts from has it: say so before any step
  // rather than act as local.
  const GlobalInjectivity g0 = global_injectivity();
  if (g0.verdict == GlobalInjectivity::Verdict::kNotDecided)
    throw InputError("injectivity", "global injectivity cannot be decided: " + g0.reason);
  if (g0.verdict == GlobalInjectivity::Verdict::kOverlap)
    throw InputError("injectivity", "the starting map is not globally injective: " + g0.reason);
}

DeformationSolver::NewtonDirection DeformationSolver::newton_direction(bool reuse, IterationRecord& rec) {
  const int s = subspace_.size();
  NewtonDirection d;
  auto t0 = Clock::now();
  d.e0 = energy_->terms(kernels_->distortion_sum(0), y_, weights_);
  rec.energy_before = d.e0.total;
  const MatS3 g = energy_->gradient_from(kernels_->distortion_gradient_sum(), y_, weights_);
  rec.gradient_norm = g.norm();
  rec.ms_gradient += ms_since(t0);

  d.gvec = Eigen::Map<const VecXd>(g.data(), 3 * s);
  VecXd& dvec = d.dvec;
  dvec = -d.gvec;
  MatXd F;                      // this step's factor (when not kept in factor_)
  const MatXd* L = &factor_.L;  // the factor dvec was solved with
  if (reuse) {
    t0 = Clock::now();
    if (!cholesky_solve_factored(factor_.L, dvec))
      throw NumericalError("projected Newton: solving with the kept Hessian factor failed");
    ++factor_.reuses;
    rec.ms_solve += ms_since(t0);
  } else if (kept_factor_direction(d.gvec, dvec, rec)) {
    rec.hessian_reused = true;
  } else {
    // The reduced Hessian is factored in place (no 3s x 3s copy per iteration) and rebuilt from the kept
    // blocks only when its factorization fails.
    std::vector<double> shifts;  // diagonal shifts added after a failed factorization, in order
    const auto shifted_hessian = [&] {
      MatXd H = energy_->hessian_from(distortion_hessian_blocks(), weights_);
      H.diagonal().array() += params_.diagonal_shift;
      for (const double add : shifts) H.diagonal().array() += add;
      return H;
    };
    t0 = Clock::now();
    F = shifted_hessian();
    rec.ms_hessian += ms_since(t0);

    t0 = Clock::now();
    bool ok = cholesky_solve(F, dvec);
    for (double extra = 1e-6; !ok && extra < 1e6; extra *= 100) {
      // PSD blocks plus a positive shift are positive definite in exact arithmetic; single-precision
      // rounding can still break that, in which case the shift grows.
      F = shifted_hessian();
      shifts.push_back(extra * (1.0 + F.diagonal().cwiseAbs().maxCoeff()));
      F.diagonal().array() += shifts.back();
      dvec = -d.gvec;
      ok = cholesky_solve(F, dvec);
    }
    if (!ok) throw NumericalError("projected Newton: the reduced Hessian is not positive definite");
    if ((dragging_ && params_.drag_hessian_reuse > 0) || params_.kept_factor_cg_steps > 0) {
      factor_ = {std::move(F), weights_, 0};
      L = &factor_.L;
    } else {
      factor_ = {};
      L = &F;
    }
    rec.ms_solve += ms_since(t0);
  }
  t0 = Clock::now();
  if (params_.newton_cg_steps > 0)
    dvec = conjugate_gradient_correction(d.gvec, dvec, *L, rec);  // leaves the kernels' direction at dvec
  else {
    kernels_->set_direction(Eigen::Map<const MatS3>(dvec.data(), s, 3));
    direction_scale_ = dvec.norm() * (1 + 1e-12);
  }
  rec.ms_solve += ms_since(t0);
  rec.newton_decrement = -d.gvec.dot(dvec);
  return d;
}

const MatXd& DeformationSolver::distortion_hessian_blocks() {
  const bool dbl = params_.hessian_precision == HessianPrecision::kDouble;
  if (hessian_blocks_.size() == 0 || hessian_blocks_double_ != dbl) {
    // At rest: built at construction from this very map. Where the kept factor's CG steps computed the
    // per-sample blocks already, the CPU kernels would compute the same ones again (the same bits either
    // way).
    if (!dbl && backend_->is_cpu() && rest_hessian_blocks_.size() > 0 && rest_y_.rows() == y_.rows() &&
        y_ == rest_y_)
      hessian_blocks_ = rest_hessian_blocks_;
    else
      hessian_blocks_ = !subset_blocks_.empty() && backend_->is_cpu()
                            ? energy_->distortion_pair_blocks_from(subset_blocks_, dbl)
                            : kernels_->distortion_pair_blocks(dbl);
    hessian_blocks_double_ = dbl;
  }
  return hessian_blocks_;
}

const std::vector<Mat9>& DeformationSolver::distortion_subset_blocks() {
  if (subset_blocks_.empty()) subset_blocks_ = energy_->subset_hessian_blocks(kernels_->current_jacobians());
  return subset_blocks_;
}

bool DeformationSolver::kept_factor_direction(const VecXd& gvec, VecXd& dvec, IterationRecord& rec) {
  // CPU only: a device assembles the Hessian in a few milliseconds, less than these host steps would take.
  if (params_.kept_factor_cg_steps <= 0 || factor_.L.size() == 0 || !backend_->is_cpu()) return false;
  const int s = subspace_.size();
  auto t0 = Clock::now();
  const std::vector<Mat9>& blocks = distortion_subset_blocks();
  rec.ms_hessian += ms_since(t0);
  t0 = Clock::now();
  // The operator the assembly would factor (shifted_hessian in newton_direction, without the extra shifts
  // of a failed factorization), through the per-sample blocks: one pass over the subset's rows of G per
  // product instead of the 36 s²|H| flops of the assembly and the factorization.
  double ms_operator = 0, ms_preconditioner = 0;  // for the trace: where the CG steps' time goes
  const auto A = [&](const VecXd& p) -> VecXd {
    const auto ta = Clock::now();
    const Eigen::Map<const MatS3> pm(p.data(), s, 3);
    const MatS3 h =
        energy_->subset_hessian_times(blocks, pm) + energy_->quadratic_hessian_times(pm, weights_);
    VecXd out = Eigen::Map<const VecXd>(h.data(), 3 * s) + params_.diagonal_shift * p;
    ms_operator += ms_since(ta);
    return out;
  };
  // The preconditioner: the kept factor, in double precision like the operator. CG amplifies rounding that
  // differs from one direction to the next: with single-precision products or a single-precision factor a
  // copy of bar_bend scaled by 1e-6 ended 2e-3 away from the original (model size 1), in double 5.1e-7.
  const auto M = [&](VecXd& r) {
    const auto tm = Clock::now();
    const bool ok = cholesky_solve_factored(factor_.L, r);
    ms_preconditioner += ms_since(tm);
    return ok;
  };
  const PcgResult r =
      preconditioned_cg(-gvec, A, M, params_.kept_factor_cg_steps, params_.kept_factor_tolerance);
  rec.kept_factor_steps = r.steps;
  rec.ms_solve += ms_since(t0);
  if (params_.trace_line_search)
    std::fprintf(
        stderr,
        "  kept factor: %d CG steps, relative residual %.3g%s, %.1f ms (operator %.1f, factor's solves "
        "%.1f)\n",
        r.steps, r.relative_residual, r.converged ? "" : " (assembling)", ms_since(t0), ms_operator,
        ms_preconditioner);
  if (!r.converged) return false;
  dvec = r.x;
  ++factor_.reuses;
  return true;
}

DeformationSolver::LineSearchEnd DeformationSolver::certified_line_search(const NewtonDirection& d,
                                                                          bool may_retry,
                                                                          IterationRecord& rec,
                                                                          const std::atomic<bool>* stop) {
  const MatS3 delta = Eigen::Map<const MatS3>(d.dvec.data(), subspace_.size(), 3);
  const auto t0 = Clock::now();
  const double slope = d.gvec.dot(d.dvec);  // < 0 for a descent direction
  LineSearchEnd end = LineSearchEnd::kExhausted;
  // A step t‖δ‖ ≤ step_tolerance · max(1, ‖ỹ + tδ‖) would end the solve anyway (converged, or blocked when
  // a trial was refused: docs/solver.md, "Stop"; ‖ỹ + tδ‖ ≥ ‖ỹ‖ − t‖δ‖), so such trials are not tried: a map
  // held at the boundary of the certified region (a fold, the distortion bound, the shape touching itself)
  // stops halving after ~20 trials instead of max_halvings.
  const double ynorm = y_.norm(), dnorm = d.dvec.norm();
  auto too_short = [&](double t) {
    return t * dnorm <= params_.step_tolerance * std::max(1.0, ynorm - t * dnorm);
  };
  double t = 1;
  screened_trials_ = 0;  // a new direction: the distortion screen starts over
  screen_.reset();
  screen_J0_.resize(0, 3);
  for (int trial = 0; trial <= params_.max_halvings; ++trial, t *= 0.5) {
    if (stop_requested(stop)) {
      end = LineSearchEnd::kInterrupted;
      break;
    }
    if (trial > 0 && too_short(t)) break;
    const MatS3 yt = y_ + t * delta;
    const EnergyTerms et = energy_->terms(kernels_->distortion_sum(t), yt, weights_);
    if (!(et.total <= d.e0.total + params_.armijo * t * slope)) {
      if (params_.trace_line_search)
        std::fprintf(stderr, "  trial t=%.4g E=%.6g > E0=%.6g (Armijo)\n", t, et.total, d.e0.total);
      ++rec.armijo_rejections;
      continue;
    }
    Certificate c = certify_trial(yt, t, delta, et, rec);
    if (!c.certified) ++rec.certificate_rejections;
    // Global injectivity: only of trials the local certificate accepted (the degree argument needs it).
    const bool accepted =
        c.certified && (params_.injectivity != InjectivityMode::kGlobal || globally_injective_trial(yt, rec));
    if (!accepted) {
      if (may_retry) {
        end = LineSearchEnd::kRetry;
        break;
      }
      continue;
    }
    accept_trial(yt, t, delta, et, std::move(c), rec);
    end = LineSearchEnd::kAccepted;
    break;
  }
  rec.ms_line_search += ms_since(t0);
  if (!rec.accepted) rec.terms = d.e0;
  return end;
}

Certificate DeformationSolver::certify_trial(const MatS3& yt, double t, const MatS3& delta,
                                             const EnergyTerms& et, IterationRecord& rec) {
  const auto tc = Clock::now();
  CertifyParams cp = certify_params(true, false);
  cp.max_refined_voxels = std::min(cp.max_refined_voxels, params_.line_search_max_refined);
  cp.base_spectral_fallback = params_.line_search_spectral_fallback;
  cp.priority_voxels = line_search_failed_;  // where the last rejected trial failed: checked first
  cp.distortion_probes = distortion_probes_;
  Certificate c;
  // The points where earlier trials failed first: when one of them still proves a violation, the trial is
  // refused without screening the samples for a new probe (the screen is most of a probe-refused trial's
  // time). Only a proof refuses, so the verdict is the certificate's.
  if (!certifier_->distortion_refuted(yt, cp, c)) {
    screen_distortion(t, cp);
    if (!perturb_lower_.empty() && perturb_y_.rows() == y_.rows() && perturb_y_ == y_) {
      cp.previous_y = &perturb_y_;  // y_ is the map certified with these bounds: Step 4e applies
      cp.previous_lower = &perturb_lower_;
      cp.previous_upper = &perturb_upper_;
      cp.perturbation_floor = params_.epsilon;                  // condition (36) then decides as without them
      if (const MatJT* dJ = kernels_->direction_jacobians()) {  // the center term from G d (Step 4e)
        cp.direction = &delta;
        cp.direction_jacobians = dJ;
        cp.direction_step = t;
        cp.direction_scale = direction_scale_;
      }
    }
    c = certifier_->certify_reduced(yt, cp);
  }
  if (!c.certified) {
    line_search_failed_ = c.failed_voxels;
    // The last rejection by the distortion bound, named in the model's frame (the stop message says it).
    distortion_rejection_ = c.distortion_failed ? frame_.from_normalized(Certificate(c)).reason : "";
    if (c.distortion_failed) {  // the next trials look there first, then where earlier trials failed
      std::vector<Vec3> probes;
      for (const CertLeaf& l : c.failing) probes.push_back(l.center);
      for (const Vec3& q : distortion_probes_)
        if (probes.size() < kMaxDistortionProbes &&
            std::find(probes.begin(), probes.end(), q) == probes.end())
          probes.push_back(q);
      distortion_probes_ = std::move(probes);
    }
  }
  rec.ms_certificate += ms_since(tc);
  if (params_.trace_line_search)
    std::fprintf(stderr,
                 "  trial t=%.4g E=%.6g cert=%d refined=%ld taken_over=%ld fallback=%ld (%s) %.1f ms "
                 "(certifier: J %.1f, "
                 "sigma %.1f, bounds %.1f, refinement %.1f, the rest %.1f)\n",
                 t, et.total, c.certified ? 1 : 0, c.refined, c.perturbed_voxels, c.fallback_voxels,
                 c.reason.c_str(), ms_since(tc), c.ms_jacobian, c.ms_sigma, c.ms_bound, c.ms_refine,
                 c.ms_total - c.ms_jacobian - c.ms_sigma - c.ms_bound - c.ms_refine);
  return c;
}

// With distortion targets, the trial's sample farthest beyond them (largest σ1/σ3 for K alone; from the
// kernels' Jacobians, which the energy has just used) becomes the first probe when it seems beyond a target:
// the certifier evaluates it exactly and refuses the trial at once if the violation is proven there
// (docs/certificate.md, "Probes"), instead of refining leaves toward a bound no certificate can reach. Only a
// proof refuses, so the verdict is the certificate's. CPU kernels only (an OpenCL backend keeps its Jacobians
// on the device).
// The line search's first trial screens every sample; the later ones (smaller steps along the same direction
// from the same map) only the samples Weyl's inequality leaves in question (DistortionScreen): the same
// probe.
void DeformationSolver::screen_distortion(double t, CertifyParams& cp) {
  const DistortionTargets targets = cp.targets();
  const MatJT* dJ = targets.any() ? kernels_->direction_jacobians() : nullptr;
  if (!dJ) return;
  const long rows = 3 * nsampling_.centers.rows();
  if (screen_J0_.rows() == 0) screen_J0_ = kernels_->current_jacobians();  // once per line search
  if (screen_J0_.rows() != dJ->rows() || screen_J0_.rows() != rows) return;
  double excess = 0;
  long i = -1;
  if (++screened_trials_ == 1) {
    i = largest_excess_sample(screen_J0_, *dJ, t, targets, &excess);
  } else {
    if (!screen_) screen_ = std::make_unique<DistortionScreen>(screen_J0_, *dJ);
    i = screen_->largest_excess_sample(t, targets, &excess);
  }
  if (i >= 0 && excess > 1)
    cp.distortion_probes.insert(cp.distortion_probes.begin(), nsampling_.centers.row(i).transpose());
}

bool DeformationSolver::globally_injective_trial(const MatS3& yt, IterationRecord& rec) {
  const auto tg = Clock::now();
  const GlobalInjectivity g = check_global(yt);
  rec.ms_global += ms_since(tg);
  if (params_.trace_line_search)
    std::fprintf(stderr, "  global: %s %.1f ms\n", to_json_literal(g.verdict), ms_since(tg));
  if (g.verdict != GlobalInjectivity::Verdict::kInjective) {
    const Vec3& x = g.overlap_point;
    global_rejection_ = g.verdict == GlobalInjectivity::Verdict::kOverlap
                            ? "the shape would pass through itself near (" + format_g(x.x()) + ", " +
                                  format_g(x.y()) + ", " + format_g(x.z()) + ")"
                            : "global injectivity not proven (" + g.reason + ")";
    ++rec.global_rejections;
    return false;
  }
  global_y_ = yt;
  global_verdict_ = g;
  return true;
}

void DeformationSolver::accept_trial(const MatS3& yt, double t, const MatS3& delta, const EnergyTerms& et,
                                     Certificate&& c, IterationRecord& rec) {
  rec.accepted = true;
  rec.step = t;
  rec.step_norm = t * delta.norm();
  rec.terms = et;
  y_ = yt;
  kernels_->accept(t);
  forget_map_hessian(hessian_blocks_, subset_blocks_);
  perturb_y_ = yt;
  perturb_lower_ = c.base_lower;
  perturb_upper_ = c.base_upper;
  cert_ = frame_.from_normalized(std::move(c));
}

void DeformationSolver::weaken_handles(IterationRecord& rec) {
  weights_.p2p = std::max(params_.min_p2p_factor * params_.lambda_p2p, weights_.p2p * params_.kappa1);
  weights_.smooth =
      std::min(params_.max_smooth_factor * params_.lambda_smooth, weights_.smooth * params_.kappa2);
  rec.weight_action += "retry,";
}

void DeformationSolver::finish_record(IterationRecord& rec, bool interrupted,
                                      const EnergyWeights& weights_at_start) {
  rec.certified = cert_.certified;
  rec.min_sigma3 = cert_.min_sigma3_center;
  rec.min_lower_bound = cert_.min_lower_bound;
  rec.refined = cert_.refined;
  const VecXd herr = handle_errors();
  rec.max_handle_error = herr.size() ? herr.maxCoeff() : 0.0;
  const std::string retries = rec.weight_action;
  if (rec.accepted && params_.dynamic_weighting) update_weights(rec);
  rec.weight_action = retries + rec.weight_action;
  if (!rec.weight_action.empty() && rec.weight_action.back() == ',') rec.weight_action.pop_back();
  if (interrupted) {
    // An interrupted iteration changes nothing, weights included (an interrupted run must equal a run limited
    // to the iterations it completed).
    weights_ = weights_at_start;
    rec.weight_action = "interrupted";
  }
}

VecXd DeformationSolver::conjugate_gradient_correction(const VecXd& gvec, const VecXd& p0, const MatXd& L,
                                                       IterationRecord& rec) {
  // The exact Hessian's products for truncated_newton_cg (newton_cg.h): the distortion part from the kernels
  // (or on the host from the current Jacobians, for a backend without them), the quadratic terms exactly.
  const int s = subspace_.size();
  const double n = energy_->num_samples();
  auto as_mat = [s](const VecXd& v) { return Eigen::Map<const MatS3>(v.data(), s, 3); };
  auto as_vec = [s](const MatS3& m) { return Eigen::Map<const VecXd>(m.data(), 3 * s); };
  const bool native = kernels_->has_hessian_products();
  MatJT J_host, dJ_host;
  if (!native) J_host = kernels_->current_jacobians();
  NewtonCgOperators ops;
  double p_norm = 0, combined_scale = 0;  // ‖p‖_F of the last iterate; Σ_k |α_k| ‖p_k‖_F
  ops.curvature = [&](const VecXd& p) {
    p_norm = p.norm();
    double dis;
    if (native) {
      kernels_->set_direction(as_mat(p));
      dis = kernels_->distortion_curvature();
    } else {
      dJ_host = energy_->jacobians(as_mat(p));
      dis = energy_->distortion_curvature(J_host, dJ_host);
    }
    return dis / n + p.dot(as_vec(energy_->quadratic_hessian_times(as_mat(p), weights_)));
  };
  ops.hessian_times = [&](const VecXd& p) -> VecXd {
    const MatS3 dis = native ? kernels_->distortion_hessian_direction_sum()
                             : energy_->distortion_hessian_times_sum(J_host, dJ_host);
    return as_vec(dis / n + energy_->quadratic_hessian_times(as_mat(p), weights_));
  };
  ops.precondition = [&](VecXd& r) { return cholesky_solve_factored(L, r); };
  ops.accepted = [&](double alpha, int k) {
    if (native) kernels_->accumulate_direction(alpha, k == 0);
    combined_scale += std::abs(alpha) * p_norm;
  };
  NewtonCgResult cg = truncated_newton_cg(gvec, p0, params_.newton_cg_steps, ops);
  rec.cg_steps = cg.steps;
  rec.cg_scale = cg.scale;
  // The kernels' direction becomes d: the accumulated Jacobians (no pass over G); with no iterate it is
  // already p0 (the first curvature set it); on the host fallback one pass.
  // direction_scale_ (CertifyParams::direction_scale): the combined Jacobians Σ_k α_k G p_k round like
  // Σ_k |α_k| ‖p_k‖ (docs/certificate.md, Step 4e); a single pass like ‖d‖.
  if (native) {
    if (cg.steps > 0) kernels_->use_accumulated_direction();
  } else {
    kernels_->set_direction(as_mat(cg.d));
  }
  const bool combined = native && cg.steps > 0;
  direction_scale_ = (combined ? std::max(combined_scale, cg.d.norm()) : cg.d.norm()) * (1 + 1e-12);
  return cg.d;
}

void DeformationSolver::update_weights(IterationRecord& rec) {
  const double l1_min = params_.min_p2p_factor * params_.lambda_p2p;
  const double l2_max = params_.max_smooth_factor * params_.lambda_smooth;
  const double e0 = params_.e0 * bbox_diag2_;
  std::string action;
  auto smooth_up = [&] {
    if (weights_.smooth < l2_max) {
      weights_.smooth = std::min(l2_max, weights_.smooth * params_.kappa2);
      action += action.empty() ? "smooth+" : ",smooth+";
    }
  };
  if (rec.terms.p2p >= e0) {
    // Far from the targets: the P2P term dominates and pulls toward the boundary of the injective maps.
    smooth_up();
    if (rec.min_lower_bound < params_.epsilon && weights_.p2p > l1_min) {
      weights_.p2p = std::max(l1_min, weights_.p2p * params_.kappa1);
      action += action.empty() ? "p2p-" : ",p2p-";
    }
  } else if (rec.certificate_rejections > 0) {
    // Close to the targets, but the full Newton step failed condition (6): smooth more.
    smooth_up();
  } else if (weights_.smooth != params_.lambda_smooth || weights_.p2p != params_.lambda_p2p) {
    // Nothing needed a change: move one factor back toward the user's weights, so that the run ends at them.
    weights_.smooth = std::max(params_.lambda_smooth, weights_.smooth / params_.kappa2);
    weights_.p2p = std::min(params_.lambda_p2p, weights_.p2p / params_.kappa1);
    action = "relax";
  }
  rec.weight_action = action;
}

SolveResult DeformationSolver::solve(const std::function<bool(const IterationRecord&)>& on_iteration,
                                     const std::atomic<bool>* stop) {
  const auto t_start = Clock::now();
  SolveResult res;
  if (energy_->num_handles() == 0) throw InputError("handles", "no handles: set_handles() first");
  for (int it = 0;; ++it) {
    if (it >= params_.max_iterations) {
      res.reason = StopReason::kMaxIterations;
      res.message = "iteration limit (" + std::to_string(params_.max_iterations) + ") reached";
      break;
    }
    if (stop_requested(stop)) {
      res.reason = StopReason::kInterrupted;
      res.message = "interrupted";
      break;
    }
    IterationRecord rec = step(stop);
    ++res.iterations;
    if (rec.weight_action == "interrupted") {
      // The cut-short iteration changed nothing; drop it from the history so that an interrupted run equals a
      // run limited to the iterations it completed.
      history_.pop_back();
      --res.iterations;
      res.reason = StopReason::kInterrupted;
      res.message = "interrupted during the line search of iteration " + std::to_string(rec.iteration);
      break;
    }
    bool done = false;
    if (!rec.accepted) {
      const bool can_adjust = params_.dynamic_weighting &&
                              weights_.p2p > params_.min_p2p_factor * params_.lambda_p2p * (1 + 1e-12);
      if (can_adjust) {
        // No certified decrease with these weights: pull less, smooth more, and try again.
        weights_.p2p = std::max(params_.min_p2p_factor * params_.lambda_p2p, weights_.p2p * params_.kappa1);
        weights_.smooth =
            std::min(params_.max_smooth_factor * params_.lambda_smooth, weights_.smooth * params_.kappa2);
        history_.back().weight_action = "p2p*,smooth* (no step)";
        rec.weight_action = history_.back().weight_action;
      } else if (rec.global_rejections > 0) {
        res.reason = StopReason::kBlocked;
        res.message = "blocked: " + global_rejection_;
        done = true;
      } else {
        res.reason = StopReason::kNoCertifiedStep;
        // The trials end at max_halvings or at the step tolerance (certified_line_search), whichever is
        // first.
        res.message = "no certified step of decreasing energy in " +
                      std::to_string(rec.armijo_rejections + rec.certificate_rejections) + " trials (" +
                      std::to_string(rec.armijo_rejections) + " energy, " +
                      std::to_string(rec.certificate_rejections) + " certificate rejections)" +
                      distortion_note();
        done = true;
      }
    } else {
      const double ynorm = std::max(1.0, y_.norm());
      const bool small_step = rec.step_norm <= params_.step_tolerance * ynorm;
      const double decrease = rec.energy_before - rec.terms.total;
      const bool small_decrease =
          decrease <= params_.energy_tolerance * std::max(std::abs(rec.energy_before), 1e-300);
      if ((small_step || small_decrease) && rec.global_rejections > 0) {
        res.reason = StopReason::kBlocked;
        res.message = "blocked: " + global_rejection_;
        done = true;
      } else if ((small_step || small_decrease) && rec.certificate_rejections > 0) {
        res.reason = StopReason::kBlocked;
        res.message = "the certificate limits the step to " + format_g(rec.step, 4) +
                      ": the map is at the boundary of the certified region" + distortion_note();
        done = true;
      } else if (small_step || small_decrease) {
        const bool changed = weights_.p2p != params_.lambda_p2p || weights_.smooth != params_.lambda_smooth;
        if (changed && params_.dynamic_weighting && weight_resets_ < params_.max_weight_resets) {
          weights_ = {params_.lambda_p2p, params_.lambda_smooth};
          ++weight_resets_;
          history_.back().weight_action = "reset";
          rec.weight_action = "reset";
        } else {
          res.reason = StopReason::kConverged;
          res.message = small_step ? "step below tolerance" : "energy decrease below tolerance";
          if (changed)
            res.message += " at adjusted weights (lambda_p2p " + format_g(weights_.p2p, 4) +
                           ", lambda_smooth " + format_g(weights_.smooth, 4) +
                           "; the reset limit max_weight_resets was reached)";
          done = true;
        }
      }
    }
    if (on_iteration && !on_iteration(rec)) {
      if (!done) {
        res.reason = StopReason::kInterrupted;
        res.message = "stopped after iteration " + std::to_string(rec.iteration);
      }
      break;
    }
    if (done) break;
  }
  res.seconds = ms_since(t_start) / 1000;
  return res;
}

}  // namespace lidef
