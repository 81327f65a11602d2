#include "lidef/compute_backend.h"

#include "lidef/deform_params.h"
#include "lidef/errors.h"

namespace lidef {
namespace {

// The reference backend: the DeformationEnergy's own Eigen/OpenMP/OpenBLAS code on host arrays.
class CpuEnergyKernels final : public EnergyKernels {
 public:
  explicit CpuEnergyKernels(const DeformationEnergy& e) : e_(e) {}
  void set_current(const MatS3& y) override {
    J_ = e_.jacobians(y);
    forget_current();
  }
  void set_direction(const MatS3& d) override {
    dJ_ = e_.jacobians(d);
    trial_t_ = 0;
  }
  double distortion_sum(double t) override {
    if (t == 0) {
      if (!has_sum0_) sum0_ = e_.distortion_sum(J_), has_sum0_ = true;
      return sum0_;
    }
    Jt_.noalias() = J_ + t * dJ_;
    trial_t_ = t;
    trial_sum_ = e_.distortion_sum(Jt_);
    return trial_sum_;
  }
  void accept(double t) override {
    // The accepted step is almost always the last trial: its Jacobians (the same expression, the same bits)
    // and its sum are the new map's, so the next iteration's energy at t = 0 costs no pass.
    const bool last_trial = trial_t_ != 0 && t == trial_t_ && Jt_.rows() == J_.rows();
    if (last_trial)
      J_.swap(Jt_);
    else
      J_ = (J_ + t * dJ_).eval();
    forget_current();
    if (last_trial) {
      sum0_ = trial_sum_;
      has_sum0_ = true;
    }
  }
  // Kept until the current map changes: an iteration whose direction is recomputed with other weights
  // (dynamic weighting's retries) asks again at the same map, and gets the same values.
  MatS3 distortion_gradient_sum() override {
    if (gradient_.rows() == 0) gradient_ = e_.distortion_gradient_sum(J_);
    return gradient_;
  }
  MatXd distortion_pair_blocks(bool double_precision) override {
    return e_.distortion_pair_blocks(J_, double_precision);
  }
  bool has_hessian_products() const override { return true; }
  MatS3 distortion_hessian_direction_sum() override { return e_.distortion_hessian_times_sum(J_, dJ_); }
  double distortion_curvature() override { return e_.distortion_curvature(J_, dJ_); }
  void accumulate_direction(double alpha, bool start) override {
    if (start)
      sum_ = alpha * dJ_;
    else
      sum_ += alpha * dJ_;
  }
  void use_accumulated_direction() override {
    dJ_.swap(sum_);
    trial_t_ = 0;
  }
  MatJT current_jacobians() override { return J_; }
  const MatJT* direction_jacobians() const override { return &dJ_; }

 private:
  void forget_current() {
    has_sum0_ = false;
    trial_t_ = 0;  // no trial of the new map's direction yet
    gradient_.resize(0, 3);
  }
  const DeformationEnergy& e_;
  MatJT J_, dJ_, sum_;
  MatJT Jt_;                            // J_ + trial_t_ dJ_ of the last trial (a kept buffer)
  double trial_t_ = 0, trial_sum_ = 0;  // the last trial's step (0: none since the map or dJ changed)
  bool has_sum0_ = false;               // sum0_ = distortion_sum(0) at J_
  double sum0_ = 0;
  MatS3 gradient_;  // distortion_gradient_sum() at J_ (0 rows: not computed)
};

class CpuBackend final : public ComputeBackend {
 public:
  std::string name() const override { return "cpu"; }
  bool is_cpu() const override { return true; }
  std::unique_ptr<EnergyKernels> energy_kernels(const DeformationEnergy& energy) const override {
    return std::make_unique<CpuEnergyKernels>(energy);
  }
  std::unique_ptr<CertifierKernels> certifier_kernels(const CertifierData&) const override { return nullptr; }
};

}  // namespace

std::shared_ptr<const ComputeBackend> cpu_backend() {
  static const auto backend = std::make_shared<const CpuBackend>();
  return backend;
}

BackendFactory cpu_backend_factory() {
  return [](const DeformParams& params, std::string* message) -> std::shared_ptr<const ComputeBackend> {
    if (params.backend == BackendKind::kOpenCL)
      throw Error("backend 'opencl' is not available in this program (built without OpenCL)");
    if (message)
      *message =
          params.backend == BackendKind::kCpu ? "backend: cpu" : "backend: cpu (auto: built without OpenCL)";
    return cpu_backend();
  };
}

}  // namespace lidef
