#define CL_HPP_TARGET_OPENCL_VERSION 120
#define CL_HPP_MINIMUM_OPENCL_VERSION 120
#define CL_HPP_ENABLE_EXCEPTIONS
#include "lidef/opencl/opencl_backend.h"

#include <clblast.h>
#include <unistd.h>

#include <CL/opencl.hpp>
#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <mutex>
#include <sstream>
#include <utility>
#include <vector>

#include "lidef/atomic_file.h"
#include "lidef/hash.h"
#include "lidef/number_format.h"
#include "lidef_kernel_source.h"  // kLidefKernelSource: opencl/kernels/lidef.cl

namespace lidef {
namespace {

const char* cl_error_name(cl_int e) {
  switch (e) {
    case CL_DEVICE_NOT_FOUND:
      return "CL_DEVICE_NOT_FOUND";
    case CL_DEVICE_NOT_AVAILABLE:
      return "CL_DEVICE_NOT_AVAILABLE";
    case CL_COMPILER_NOT_AVAILABLE:
      return "CL_COMPILER_NOT_AVAILABLE";
    case CL_MEM_OBJECT_ALLOCATION_FAILURE:
      return "CL_MEM_OBJECT_ALLOCATION_FAILURE (out of device memory)";
    case CL_OUT_OF_RESOURCES:
      return "CL_OUT_OF_RESOURCES (out of device memory or resources)";
    case CL_OUT_OF_HOST_MEMORY:
      return "CL_OUT_OF_HOST_MEMORY";
    case CL_BUILD_PROGRAM_FAILURE:
      return "CL_BUILD_PROGRAM_FAILURE";
    case CL_INVALID_VALUE:
      return "CL_INVALID_VALUE";
    case CL_INVALID_BUFFER_SIZE:
      return "CL_INVALID_BUFFER_SIZE (buffer larger than the device allows)";
    case CL_INVALID_KERNEL_ARGS:
      return "CL_INVALID_KERNEL_ARGS";
    case CL_INVALID_WORK_GROUP_SIZE:
      return "CL_INVALID_WORK_GROUP_SIZE";
    case CL_INVALID_BINARY:
      return "CL_INVALID_BINARY";
    case -1001:
      return "CL_PLATFORM_NOT_FOUND_KHR (no OpenCL platform installed)";
    default:
      return "OpenCL error";
  }
}

// Runs f; turns OpenCL and CLBlast failures into OpenCLError("OpenCL (<device>): <stage>: ...").
template <class F>
auto guarded(const std::string& device, const std::string& stage, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const cl::Error& e) {
    throw OpenCLError("OpenCL (" + device + "): " + stage + ": " + e.what() + " returned " +
                      std::to_string(e.err()) + " " + cl_error_name(e.err()));
  } catch (const std::bad_alloc&) {
    throw OpenCLError("OpenCL (" + device + "): " + stage + ": out of host memory");
  }
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string trim(std::string s) {
  while (!s.empty() && (s.back() == '\0' || std::isspace(static_cast<unsigned char>(s.back())))) s.pop_back();
  size_t b = 0;
  while (b < s.size() && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  return s.substr(b);
}

std::string type_name(cl_device_type t) {
  if (t & CL_DEVICE_TYPE_GPU) return "GPU";
  if (t & CL_DEVICE_TYPE_CPU) return "CPU";
  if (t & CL_DEVICE_TYPE_ACCELERATOR) return "accelerator";
  return "other";
}

bool has_fp64(const cl::Device& d) {
  const std::string ext = d.getInfo<CL_DEVICE_EXTENSIONS>();
  if (ext.find("cl_khr_fp64") != std::string::npos) return true;
  try {
    return d.getInfo<CL_DEVICE_DOUBLE_FP_CONFIG>() != 0;
  } catch (const cl::Error&) {
    return false;
  }
}

void check_clblast(clblast::StatusCode st, const std::string& device, const std::string& stage) {
  if (st != clblast::StatusCode::kSuccess)
    throw OpenCLError("OpenCL (" + device + "): " + stage + ": CLBlast returned status " +
                      std::to_string(static_cast<int>(st)) +
                      (static_cast<int>(st) == CL_MEM_OBJECT_ALLOCATION_FAILURE ||
                               static_cast<int>(st) == CL_OUT_OF_RESOURCES
                           ? " (out of device memory)"
                           : ""));
}

// The context, queue and built program on one device, shared by every kernel object of one backend.
struct Device {
  cl::Platform platform;
  cl::Device device;
  cl::Context context;
  cl::CommandQueue queue;
  cl::Program program;
  std::string label;  // "<device> (<platform>)"
  size_t max_group = 1;
  // The device is the host's CPU (PoCL): dense products go to the host BLAS and the streaming kernels use the
  // row layouts with explicit vectors (lidef.cl). LIDEF_OPENCL_AS_GPU=1 treats it as a GPU anyway (tests of
  // the GPU paths on PoCL).
  bool cpu_device = false;
  unsigned long long max_alloc = 0, global_mem = 0;
  std::mutex mutex;  // kernels of one backend are used by one thread at a time; this guards the queue anyway
};

// Builds the program from source, or loads it from the binary cache (`dir`/<hash>.bin); writes the cache
// after a build (temp file + rename, so that concurrent processes never read a half-written binary).
cl::Program build_program(Device& d, const std::string& dir, bool broken, std::string* how) {
  const std::string options = "-cl-std=CL1.2";
  const std::string key = std::string(kLidefKernelSource) + (broken ? "|broken" : "") + "|" +
                          d.platform.getInfo<CL_PLATFORM_VERSION>() + "|" +
                          d.device.getInfo<CL_DEVICE_NAME>() + "|" + d.device.getInfo<CL_DRIVER_VERSION>() +
                          "|" + options;
  const std::filesystem::path path = std::filesystem::path(dir) / (hex64(fnv1a64(key)) + ".bin");
  std::error_code ec;
  if (!dir.empty() && std::filesystem::exists(path, ec)) {
    std::ifstream in(path, std::ios::binary);
    std::vector<unsigned char> bin((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    try {
      cl::Program::Binaries bins{bin};
      cl::Program p(d.context, {d.device}, bins);
      p.build({d.device}, options.c_str());
      *how = "kernels loaded from the cache " + path.string();
      return p;
    } catch (const cl::Error&) {
      // A stale or foreign binary: rebuild from source below.
    }
  }
  std::string source = kLidefKernelSource;
  // Test hook (parameter test_break_kernels): a line that does not compile, to exercise the failure path.
  if (broken) source += "\nthis line is not OpenCL C;\n";
  cl::Program p(d.context, source);
  try {
    p.build({d.device}, options.c_str());
  } catch (const cl::Error& e) {
    std::string log;
    try {
      log = p.getBuildInfo<CL_PROGRAM_BUILD_LOG>(d.device);
    } catch (...) {
    }
    throw OpenCLError("OpenCL (" + d.label + "): building the kernels failed (" + cl_error_name(e.err()) +
                      "):\n" + trim(log));
  }
  *how = "kernels compiled";
  if (!dir.empty()) {
    try {
      const auto bins = p.getInfo<CL_PROGRAM_BINARIES>();
      if (!bins.empty() && !bins[0].empty()) {
        std::filesystem::create_directories(dir, ec);
        try {
          write_file_atomic(path.string(), [&](std::ostream& out) {
            out.write(reinterpret_cast<const char*>(bins[0].data()),
                      static_cast<std::streamsize>(bins[0].size()));
          });
          *how += ", cached in " + path.string();
        } catch (const InputError&) {
          // A cache that cannot be written only costs the next start a compile.
        }
      }
    } catch (const cl::Error&) {
      // No binaries from this driver: every start compiles.
    }
  }
  return p;
}

// Sets a kernel's arguments 0, 1, 2, ... to args, in order.
template <class... Args>
void set_args(cl::Kernel& k, const Args&... args) {
  cl_uint index = 0;
  (k.setArg(index++, args), ...);
}

size_t round_up(size_t x, size_t m) {
  return (x + m - 1) / m * m;
}

// Work-group size for the reductions: a power of two the device accepts.
size_t reduction_group(const Device& d) {
  size_t ls = 1;
  while (ls * 2 <= std::min<size_t>(256, d.max_group)) ls *= 2;
  return ls;
}

template <class T>
cl::Buffer make_buffer(Device& d, size_t count, const std::string& what,
                       cl_mem_flags flags = CL_MEM_READ_WRITE, const T* data = nullptr) {
  const unsigned long long bytes = static_cast<unsigned long long>(std::max<size_t>(count, 1)) * sizeof(T);
  if (bytes > d.max_alloc)
    throw OpenCLError("OpenCL (" + d.label + "): " + what + " needs a buffer of " +
                      std::to_string(bytes >> 20) + " MiB; the device allows at most " +
                      std::to_string(d.max_alloc >> 20) +
                      " MiB per buffer (use fewer samples or a smaller reduced_dof, or --backend cpu)");
  return guarded(d.label, what, [&] {
    cl::Buffer b(d.context, flags | (data ? CL_MEM_COPY_HOST_PTR : 0), static_cast<size_t>(bytes),
                 const_cast<T*>(data));
    return b;
  });
}

// ------------------------------------------------------------------------------------------------ energy

class OpenCLEnergyKernels final : public EnergyKernels {
 public:
  // `e` must outlive this object (the solver owns both).
  OpenCLEnergyKernels(std::shared_ptr<Device> dev, const DeformationEnergy& e) : d_(std::move(dev)), e_(e) {
    const MatXfR& G = e.gradient_matrix();
    R_ = G.rows();
    s_ = static_cast<int>(G.cols());
    n_ = R_ / 3;
    const std::vector<int>& subset = e.hessian_subset();
    m_ = static_cast<int>(subset.size());
    // Gt: s by R column-major = G transposed, so that adjacent work-items (rows) read adjacent words.
    std::vector<float> Gt(static_cast<size_t>(R_) * s_);
    for (long r = 0; r < R_; ++r)
      for (int k = 0; k < s_; ++k) Gt[static_cast<size_t>(k) * R_ + r] = G(r, k);
    Gt_ = make_buffer<float>(*d_, Gt.size(), "uploading the reduced basis gradients", CL_MEM_READ_ONLY,
                             Gt.data());
    Gt.clear();
    Gt.shrink_to_fit();
    if (d_->cpu_device) {  // G as the host stores it, for jacobians_rows and gradient_rows_partial (lidef.cl)
      Grow_ = make_buffer<float>(*d_, G.size(), "uploading the reduced basis gradients", CL_MEM_READ_ONLY,
                                 G.data());
      chunks_ = (R_ + kRowsPerChunk - 1) / kRowsPerChunk;
      partial_g_ = make_buffer<double>(*d_, static_cast<size_t>(round_up(chunks_, 8)) * 3 * s_,
                                       "allocating gradient partial sums");
    }
    const MatXfR& GH = e.subset_gradient_matrix();  // 3m by s row-major
    GHf_ = make_buffer<float>(*d_, GH.size(), "uploading the Hessian subset", CL_MEM_READ_ONLY, GH.data());
    subset_ =
        make_buffer<int>(*d_, subset.size(), "uploading the Hessian subset", CL_MEM_READ_ONLY, subset.data());
    // Volume weights (the mesh domain's refined leaves weigh less): per sample, and per Hessian block as the
    // CPU path forms them; all 1 and 1/|H| on a uniform sampling, which reproduces the unweighted sums
    // exactly.
    const VecXd w = e.weighted() ? e.sample_weights() : VecXd::Ones(n_);
    const VecXd bw = e.subset_block_weights();
    w_ = make_buffer<double>(*d_, w.size(), "uploading the sample weights", CL_MEM_READ_ONLY, w.data());
    bw_ = make_buffer<double>(*d_, bw.size(), "uploading the Hessian block weights", CL_MEM_READ_ONLY,
                              bw.data());
    y_ = make_buffer<double>(*d_, 3 * s_, "allocating coefficients");
    J_ = make_buffer<double>(*d_, 3 * R_, "allocating Jacobians");
    dJ_ = make_buffer<double>(*d_, 3 * R_, "allocating Jacobians");
    P_ = make_buffer<double>(*d_, 3 * R_, "allocating energy gradients");
    g_ = make_buffer<double>(*d_, 3 * s_, "allocating the gradient");
    ls_ = reduction_group(*d_);
    groups_ = round_up(n_, ls_) / ls_;
    partial_ = make_buffer<double>(*d_, groups_, "allocating partial sums");
    blocks_ = make_buffer<double>(*d_, static_cast<size_t>(m_) * 81, "allocating Hessian blocks");
    guarded(d_->label, "creating kernels", [&] {
      k_jac_ = cl::Kernel(d_->program, d_->cpu_device ? "jacobians_rows" : "jacobians");
      k_sum_ = cl::Kernel(d_->program, "sd_sum");
      k_grad_ = cl::Kernel(d_->program, "sd_gradient");
      k_red_ = cl::Kernel(d_->program, "gradient_reduce");
      k_gpart_ = cl::Kernel(d_->program, "gradient_rows_partial");
      k_gsum_ = cl::Kernel(d_->program, "sum_partials");
      k_axpy_ = cl::Kernel(d_->program, "axpy_J");
      k_psd_ = cl::Kernel(d_->program, "psd_blocks");
      k_wf_ = cl::Kernel(d_->program, "fill_w_float");
      k_wd_ = cl::Kernel(d_->program, "fill_w_double");
      k_htimes_ = cl::Kernel(d_->program, "sd_hessian_times");
      k_curv_ = cl::Kernel(d_->program, "sd_curvature");
      k_scale_add_ = cl::Kernel(d_->program, "scale_add_J");
      return 0;
    });
    if (!d_->cpu_device) warm_up();
  }

  // CLBlast compiles its GEMM kernels at the first call of a shape and precision in each process (about a
  // second on a GPU driver): do that here, with the solver's shape, so that it is preprocessing, not the
  // first Newton iteration.
  void warm_up() {
    Wf_ = make_buffer<float>(*d_, static_cast<size_t>(3) * m_ * 6 * s_, "allocating the Hessian product");
    Bf_ = make_buffer<float>(*d_, static_cast<size_t>(s_) * 6 * s_, "allocating the Hessian blocks");
    cl_command_queue q = d_->queue();
    check_clblast(clblast::Gemm<float>(clblast::Layout::kColMajor, clblast::Transpose::kNo,
                                       clblast::Transpose::kYes, s_, 6 * s_, 3 * m_, 1.0f, GHf_(), 0, s_,
                                       Wf_(), 0, 6 * s_, 0.0f, Bf_(), 0, s_, &q),
                  d_->label, "Hessian product (CLBlast sgemm, first call)");
    guarded(d_->label, "Hessian product (first call)", [&] {
      d_->queue.finish();
      return 0;
    });
  }

  void run_psd_blocks() {
    set_args(k_psd_, J_, subset_, m_, bw_, blocks_);
    d_->queue.enqueueNDRangeKernel(k_psd_, cl::NullRange, cl::NDRange(round_up(m_, 64)), cl::NDRange(64));
  }

  void set_current(const MatS3& y) override { jacobians(y, J_, "Jacobians at the samples"); }
  void set_direction(const MatS3& dir) override { jacobians(dir, dJ_, "Jacobians along the direction"); }

  double distortion_sum(double t) override {
    std::lock_guard<std::mutex> lock(d_->mutex);
    return summed_over_groups(k_sum_, "symmetric Dirichlet energy", [&] {
      set_args(k_sum_, J_, dJ_, t, t != 0 ? 1 : 0, static_cast<cl_long>(n_), w_);
      return 6;
    });
  }

  void accept(double t) override {
    std::lock_guard<std::mutex> lock(d_->mutex);
    guarded(d_->label, "accepting the step", [&] {
      set_args(k_axpy_, J_, dJ_, t, static_cast<cl_long>(3 * R_));
      d_->queue.enqueueNDRangeKernel(k_axpy_, cl::NullRange, cl::NDRange(round_up(3 * R_, 64)),
                                     cl::NDRange(64));
      d_->queue.finish();
      return 0;
    });
  }

  MatS3 distortion_gradient_sum() override {
    std::lock_guard<std::mutex> lock(d_->mutex);
    MatS3 g(s_, 3);
    guarded(d_->label, "energy gradient", [&] {
      set_args(k_grad_, J_, static_cast<cl_long>(n_), w_, P_);
      d_->queue.enqueueNDRangeKernel(k_grad_, cl::NullRange, cl::NDRange(round_up(n_, 64)), cl::NDRange(64));
      transpose_sum_of_P(g);
      return 0;
    });
    return g;
  }

  // The exact Hessian's products along dJ_ at J_, on the device: the conjugate-gradient correction then
  // needs no pass over G and no Jacobians on the host.
  bool has_hessian_products() const override { return true; }

  MatS3 distortion_hessian_direction_sum() override {
    std::lock_guard<std::mutex> lock(d_->mutex);
    MatS3 h(s_, 3);
    guarded(d_->label, "Hessian times the direction", [&] {
      set_args(k_htimes_, J_, dJ_, static_cast<cl_long>(n_), w_, P_);
      d_->queue.enqueueNDRangeKernel(k_htimes_, cl::NullRange, cl::NDRange(round_up(n_, 64)),
                                     cl::NDRange(64));
      transpose_sum_of_P(h);
      return 0;
    });
    return h;
  }

  double distortion_curvature() override {
    std::lock_guard<std::mutex> lock(d_->mutex);
    return summed_over_groups(k_curv_, "curvature along the direction", [&] {
      set_args(k_curv_, J_, dJ_, static_cast<cl_long>(n_), w_);
      return 4;
    });
  }

  void accumulate_direction(double alpha, bool start) override {
    std::lock_guard<std::mutex> lock(d_->mutex);
    if (!sum_()) sum_ = make_buffer<double>(*d_, 3 * R_, "allocating Jacobians");
    guarded(d_->label, "combining the direction", [&] {
      set_args(k_scale_add_, sum_, dJ_, alpha, start ? 1 : 0, static_cast<cl_long>(3 * R_));
      d_->queue.enqueueNDRangeKernel(k_scale_add_, cl::NullRange, cl::NDRange(round_up(3 * R_, 64)),
                                     cl::NDRange(64));
      return 0;
    });
  }

  // Every kernel takes its buffers as arguments at each call, so swapping the handles is enough.
  void use_accumulated_direction() override {
    std::lock_guard<std::mutex> lock(d_->mutex);
    if (!sum_()) throw OpenCLError("OpenCL (" + d_->label + "): no direction was accumulated before use");
    std::swap(dJ_, sum_);
  }

  MatXd distortion_pair_blocks(bool double_precision) override {
    std::lock_guard<std::mutex> lock(d_->mutex);
    const size_t wsize = static_cast<size_t>(3) * m_ * 6 * s_;
    MatXd out(s_, 6 * s_);
    if (d_->cpu_device) {
      // The device is this CPU: CLBlast's generic kernels under PoCL run the product ~10x slower than
      // OpenBLAS (docs/benchmarks.md), and host and device share the memory, so the 9x9 blocks (|H| x 81
      // doubles) come back and the host BLAS forms the product
      // (DeformationEnergy::distortion_pair_blocks_from).
      std::vector<double> flat(static_cast<size_t>(m_) * 81);
      guarded(d_->label, "Hessian blocks", [&] {
        run_psd_blocks();
        d_->queue.enqueueReadBuffer(blocks_, CL_TRUE, 0, flat.size() * sizeof(double), flat.data());
        return 0;
      });
      std::vector<Mat9> blocks(m_);
      for (int k = 0; k < m_; ++k)
        blocks[k] = Eigen::Map<const Mat9>(&flat[81 * static_cast<size_t>(k)]);  // symmetric
      return e_.distortion_pair_blocks_from(blocks, double_precision);
    }
    if (double_precision && !Wd_()) {
      Wd_ = make_buffer<double>(*d_, wsize, "allocating the double-precision Hessian product");
      Bd_ = make_buffer<double>(*d_, static_cast<size_t>(s_) * 6 * s_, "allocating the Hessian blocks");
    }
    if (double_precision && !GHd_()) {
      const MatXdR GHd = e_.subset_gradient_matrix().cast<double>();
      GHd_ =
          make_buffer<double>(*d_, GHd.size(), "uploading the Hessian subset", CL_MEM_READ_ONLY, GHd.data());
    }
    if (!double_precision && !Wf_()) {
      Wf_ = make_buffer<float>(*d_, wsize, "allocating the Hessian product");
      Bf_ = make_buffer<float>(*d_, static_cast<size_t>(s_) * 6 * s_, "allocating the Hessian blocks");
    }
    guarded(d_->label, "Hessian blocks", [&] {
      run_psd_blocks();
      cl::Kernel& kw = double_precision ? k_wd_ : k_wf_;
      set_args(kw, blocks_, double_precision ? GHd_ : GHf_, m_, s_, double_precision ? Wd_ : Wf_);
      d_->queue.enqueueNDRangeKernel(
          kw, cl::NullRange, cl::NDRange(round_up(3 * m_, 16), round_up(6 * s_, 16)), cl::NDRange(16, 16));
      cl_command_queue q = d_->queue();
      // Ball (s by 6s, column-major) = GHᵀ W: row-major GH (3m by s) is column-major GHᵀ, row-major W is
      // column-major Wᵀ — the same call as the CPU's cblas_sgemm.
      if (double_precision) {
        check_clblast(clblast::Gemm<double>(clblast::Layout::kColMajor, clblast::Transpose::kNo,
                                            clblast::Transpose::kYes, s_, 6 * s_, 3 * m_, 1.0, GHd_(), 0, s_,
                                            Wd_(), 0, 6 * s_, 0.0, Bd_(), 0, s_, &q),
                      d_->label, "Hessian product (CLBlast dgemm)");
        d_->queue.enqueueReadBuffer(Bd_, CL_TRUE, 0, out.size() * sizeof(double), out.data());
      } else {
        check_clblast(clblast::Gemm<float>(clblast::Layout::kColMajor, clblast::Transpose::kNo,
                                           clblast::Transpose::kYes, s_, 6 * s_, 3 * m_, 1.0f, GHf_(), 0, s_,
                                           Wf_(), 0, 6 * s_, 0.0f, Bf_(), 0, s_, &q),
                      d_->label, "Hessian product (CLBlast sgemm)");
        Eigen::MatrixXf f(s_, 6 * s_);
        d_->queue.enqueueReadBuffer(Bf_, CL_TRUE, 0, f.size() * sizeof(float), f.data());
        out = f.cast<double>();
      }
      return 0;
    });
    return out;
  }

  MatJT current_jacobians() override {
    std::lock_guard<std::mutex> lock(d_->mutex);
    Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> J(R_, 3);
    guarded(d_->label, "reading Jacobians", [&] {
      d_->queue.enqueueReadBuffer(J_, CL_TRUE, 0, J.size() * sizeof(double), J.data());
      return 0;
    });
    return J;
  }

 private:
  // Runs k, a kernel of one work-item per sample that writes its work-groups' tree sums: set_leading_args
  // sets the arguments before the sums' buffer and scratch and returns the index of the buffer's. The groups'
  // sums are added on the host in group order (deterministic). The caller holds the lock.
  template <class SetLeadingArgs>
  double summed_over_groups(cl::Kernel& k, const char* what, const SetLeadingArgs& set_leading_args) {
    std::vector<double> part(groups_);
    guarded(d_->label, what, [&] {
      const int at = set_leading_args();
      k.setArg(at, partial_);
      k.setArg(at + 1, cl::Local(ls_ * sizeof(double)));
      d_->queue.enqueueNDRangeKernel(k, cl::NullRange, cl::NDRange(groups_ * ls_), cl::NDRange(ls_));
      d_->queue.enqueueReadBuffer(partial_, CL_TRUE, 0, groups_ * sizeof(double), part.data());
      return 0;
    });
    double sum = 0;
    for (double p : part) sum += p;
    return sum;
  }

  // out (s by 3) = Gᵀ P_ (P_ in the JT layout, filled by the caller's kernel): on a GPU one work-group per
  // basis function over Gt_; on a CPU device row chunks of G's host layout, their partial sums added in
  // order. The caller holds the lock and runs this inside `guarded`.
  void transpose_sum_of_P(MatS3& out) {
    if (d_->cpu_device) {
      set_args(k_gpart_, Grow_, static_cast<cl_long>(R_), s_, P_, kRowsPerChunk, partial_g_);
      d_->queue.enqueueNDRangeKernel(k_gpart_, cl::NullRange, cl::NDRange(round_up(chunks_, 8)),
                                     cl::NDRange(8));
      set_args(k_gsum_, partial_g_, static_cast<int>(chunks_), 3 * s_, g_);
      d_->queue.enqueueNDRangeKernel(k_gsum_, cl::NullRange, cl::NDRange(round_up(3 * s_, 64)),
                                     cl::NDRange(64));
    } else {
      set_args(k_red_, Gt_, static_cast<cl_long>(R_), s_, P_, g_, cl::Local(3 * ls_ * sizeof(double)));
      d_->queue.enqueueNDRangeKernel(k_red_, cl::NullRange, cl::NDRange(s_ * ls_), cl::NDRange(ls_));
    }
    d_->queue.enqueueReadBuffer(g_, CL_TRUE, 0, 3 * s_ * sizeof(double), out.data());  // column-major s by 3
  }

  void jacobians(const MatS3& y, cl::Buffer& out, const char* stage) {
    std::lock_guard<std::mutex> lock(d_->mutex);
    guarded(d_->label, stage, [&] {
      d_->queue.enqueueWriteBuffer(y_, CL_FALSE, 0, 3 * s_ * sizeof(double), y.data());
      set_args(k_jac_, d_->cpu_device ? Grow_ : Gt_, static_cast<cl_long>(R_), s_, y_, out);
      d_->queue.enqueueNDRangeKernel(k_jac_, cl::NullRange, cl::NDRange(round_up(R_, 64)), cl::NDRange(64));
      d_->queue.finish();
      return 0;
    });
  }

  std::shared_ptr<Device> d_;
  const DeformationEnergy& e_;
  long R_ = 0, n_ = 0;
  int s_ = 0, m_ = 0;
  size_t ls_ = 64, groups_ = 1;
  static constexpr int kRowsPerChunk = 96;  // 32 samples per partial sum (CPU devices)
  long chunks_ = 0;
  cl::Buffer partial_g_;
  cl::Buffer Gt_, Grow_, GHf_, GHd_, subset_, y_, J_, dJ_, P_, g_, partial_, blocks_, w_, bw_, Wf_, Wd_, Bf_,
      Bd_;
  cl::Buffer sum_;  // the combined conjugate-gradient direction's Jacobians (allocated at first use)
  cl::Kernel k_gpart_, k_gsum_;
  cl::Kernel k_jac_, k_sum_, k_grad_, k_red_, k_axpy_, k_psd_, k_wf_, k_wd_, k_htimes_, k_curv_, k_scale_add_;
};

// ------------------------------------------------------------------------------------------------
// certificate

// Values per octree node that eval_nodes writes (kNodeOut in kernels/lidef.cl, the same layout).
constexpr long kNodeOut = 7;

class OpenCLCertifierKernels final : public CertifierKernels {
 public:
  OpenCLCertifierKernels(std::shared_ptr<Device> dev, const CertifierData& data)
      : d_(std::move(dev)), N_(data.voxels), m_(data.m) {
    const Cage& cage = *data.cage;
    if (m_ > 0 && d_->cpu_device) {
      // The host's layout (blocks of 9 rows per voxel) for certify_rows_blocks.
      GHt_ = make_buffer<float>(*d_, static_cast<size_t>(9) * m_ * N_,
                                "uploading the certificate's basis derivatives", CL_MEM_READ_ONLY, data.GH);
    } else if (m_ > 0) {
      // GHt[(row m + k) N + i]: adjacent work-items (voxels) read adjacent words.
      std::vector<float> t(static_cast<size_t>(9) * m_ * N_);
      for (long i = 0; i < N_; ++i) {
        const float* blk = data.GH + static_cast<size_t>(i) * 9 * m_;
        for (long q = 0; q < 9 * m_; ++q) t[static_cast<size_t>(q) * N_ + i] = blk[q];
      }
      GHt_ = make_buffer<float>(*d_, t.size(), "uploading the certificate's basis derivatives",
                                CL_MEM_READ_ONLY, t.data());
    }
    nf_ = cage.num_faces();
    std::vector<double> faces(static_cast<size_t>(12) * nf_);
    for (int f = 0; f < nf_; ++f) {
      Vec3 x[3];
      for (int k = 0; k < 3; ++k) x[k] = cage.V.row(cage.F(f, k)).transpose();
      for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) faces[12 * f + 3 * k + c] = x[k](c);
      for (int k = 0; k < 3; ++k) faces[12 * f + 9 + k] = (x[(k + 1) % 3] - x[(k + 2) % 3]).norm();
    }
    faces_ = make_buffer<double>(*d_, faces.size(), "uploading the cage", CL_MEM_READ_ONLY, faces.data());
    E_ = static_cast<int>(data.edge_u.size());
    std::vector<double> edges(static_cast<size_t>(6) * E_);
    for (int e = 0; e < E_; ++e)
      for (int c = 0; c < 3; ++c) {
        edges[6 * e + c] = data.edge_u[e](c);
        edges[6 * e + 3 + c] = data.edge_w[e](c);
      }
    edges_ =
        make_buffer<double>(*d_, edges.size(), "uploading the cage edges", CL_MEM_READ_ONLY, edges.data());
    delta_ = make_buffer<double>(*d_, E_, "allocating edge norms");
    fm_ = make_buffer<double>(*d_, static_cast<size_t>(37) * nf_, "allocating face matrices");
    if (m_ > 0) {
      Y_ = make_buffer<double>(*d_, 3 * m_, "allocating coefficients");
      s3_ = make_buffer<double>(*d_, N_, "allocating certificate outputs");
      s1_ = make_buffer<double>(*d_, N_, "allocating certificate outputs");
      hn_ = make_buffer<double>(*d_, N_, "allocating certificate outputs");
      T_ = make_buffer<double>(*d_, N_, "allocating certificate outputs");
      unres_ = make_buffer<double>(*d_, N_, "allocating certificate outputs");
      JH_ = make_buffer<double>(*d_, 27 * static_cast<size_t>(N_), "allocating certificate Jacobians");
    }
    guarded(d_->label, "creating kernels", [&] {
      k_rows_ = cl::Kernel(d_->program, d_->cpu_device ? "certify_rows_blocks" : "certify_rows");
      k_finish_ = cl::Kernel(d_->program, "certify_finish");
      k_nodes_ = cl::Kernel(d_->program, "eval_nodes");
      return 0;
    });
  }

  void set_factors(bool third, const float* F, long edges) override {
    if (edges != E_) throw OpenCLError("OpenCL (" + d_->label + "): edge factor matrix has the wrong size");
    std::vector<float> t(static_cast<size_t>(E_) * N_);
    for (long i = 0; i < N_; ++i)
      for (int e = 0; e < E_; ++e) t[static_cast<size_t>(e) * N_ + i] = F[static_cast<size_t>(i) * E_ + e];
    (third ? F3_ : F1_) = make_buffer<float>(*d_, t.size(), "uploading the certificate's edge factors",
                                             CL_MEM_READ_ONLY, t.data());
  }

  void base_stage(const double* Y, bool third, const VecXd& delta, VecXd& sigma3, VecXd& sigma1, VecXd& hnorm,
                  VecXd& T, std::vector<char>& unresolved) override {
    if (m_ == 0) throw OpenCLError("OpenCL (" + d_->label + "): no stored derivatives for the base stage");
    std::lock_guard<std::mutex> lock(d_->mutex);
    sigma3.resize(N_);
    sigma1.resize(N_);
    hnorm.resize(N_);
    T.resize(N_);
    std::vector<double> unres(N_);
    guarded(d_->label, "certificate base stage", [&] {
      d_->queue.enqueueWriteBuffer(Y_, CL_FALSE, 0, 3 * m_ * sizeof(double), Y);
      d_->queue.enqueueWriteBuffer(delta_, CL_FALSE, 0, E_ * sizeof(double), delta.data());
      const int rows = third ? 9 : 3;  // the first-order bound needs no Hessian
      set_args(k_rows_, GHt_, static_cast<cl_long>(N_), static_cast<int>(m_), Y_, rows, JH_);
      d_->queue.enqueueNDRangeKernel(k_rows_, cl::NullRange, cl::NDRange(round_up(N_, 64)), cl::NDRange(64));
      set_args(k_finish_, JH_, static_cast<cl_long>(N_), third ? 1 : 0, third ? F3_ : F1_, E_, delta_, s3_,
               hn_, T_, unres_, s1_);
      d_->queue.enqueueNDRangeKernel(k_finish_, cl::NullRange, cl::NDRange(round_up(N_, 64)),
                                     cl::NDRange(64));
      d_->queue.enqueueReadBuffer(s3_, CL_FALSE, 0, N_ * sizeof(double), sigma3.data());
      d_->queue.enqueueReadBuffer(s1_, CL_FALSE, 0, N_ * sizeof(double), sigma1.data());
      d_->queue.enqueueReadBuffer(hn_, CL_FALSE, 0, N_ * sizeof(double), hnorm.data());
      d_->queue.enqueueReadBuffer(T_, CL_FALSE, 0, N_ * sizeof(double), T.data());
      d_->queue.enqueueReadBuffer(unres_, CL_TRUE, 0, N_ * sizeof(double), unres.data());
      return 0;
    });
    unresolved.resize(N_);
    for (long i = 0; i < N_; ++i) unresolved[i] = unres[i] != 0;
  }

  void evaluate_nodes(const std::vector<Mat3>& A, const std::vector<std::array<Mat3, 3>>& AD,
                      const std::vector<double>& A_abs, const VecXd& delta, bool third, const MatX3d& centers,
                      const VecXd& radii, std::vector<NodeValues>& out) override {
    std::lock_guard<std::mutex> lock(d_->mutex);
    const long count = centers.rows();
    out.resize(count);
    if (count == 0) return;
    std::vector<double> fm(static_cast<size_t>(37) * nf_);
    for (int f = 0; f < nf_; ++f) {
      double* F = &fm[37 * static_cast<size_t>(f)];
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) {
          F[3 * a + b] = A[f](a, b);
          for (int k = 0; k < 3; ++k) F[9 + 9 * k + 3 * a + b] = AD[f][k](a, b);
        }
      F[36] = A_abs[f];
    }
    std::vector<double> c(3 * count), res(kNodeOut * count);
    for (long j = 0; j < count; ++j)
      for (int q = 0; q < 3; ++q) c[3 * j + q] = centers(j, q);
    if (count > cap_) {
      cap_ = std::max<long>(count, 2 * cap_);
      centers_ = make_buffer<double>(*d_, 3 * cap_, "allocating octree nodes");
      radii_ = make_buffer<double>(*d_, cap_, "allocating octree nodes");
      out_ = make_buffer<double>(*d_, kNodeOut * cap_, "allocating octree nodes");
    }
    guarded(d_->label, "octree node evaluation", [&] {
      d_->queue.enqueueWriteBuffer(fm_, CL_FALSE, 0, fm.size() * sizeof(double), fm.data());
      d_->queue.enqueueWriteBuffer(delta_, CL_FALSE, 0, E_ * sizeof(double), delta.data());
      d_->queue.enqueueWriteBuffer(centers_, CL_FALSE, 0, c.size() * sizeof(double), c.data());
      d_->queue.enqueueWriteBuffer(radii_, CL_FALSE, 0, count * sizeof(double), radii.data());
      set_args(k_nodes_, centers_, radii_, static_cast<cl_long>(count), faces_, fm_, nf_, third ? 1 : 0,
               edges_, delta_, E_, out_);
      d_->queue.enqueueNDRangeKernel(k_nodes_, cl::NullRange, cl::NDRange(round_up(count, 32)),
                                     cl::NDRange(32));
      d_->queue.enqueueReadBuffer(out_, CL_TRUE, 0, res.size() * sizeof(double), res.data());
      return 0;
    });
    // Named fields, not a braced list: NodeValues grew fields (the combined bound's, CPU only) and a
    // positional list silently put the sign flag into one of them.
    for (long j = 0; j < count; ++j) {
      NodeValues& v = out[j];
      v = NodeValues();
      const double* r = &res[kNodeOut * j];
      v.sigma3 = r[0];
      v.hnorm = r[1];
      v.own_bound = r[2];
      v.scale_J = r[3];
      v.scale_H = r[4];
      v.sign_unresolved = r[5] != 0;
      v.sigma1 = r[6];
    }
  }

 private:
  std::shared_ptr<Device> d_;
  long N_ = 0, m_ = 0, cap_ = 0;
  int nf_ = 0, E_ = 0;
  cl::Buffer GHt_, JH_, faces_, edges_, delta_, fm_, Y_, s3_, s1_, hn_, T_, unres_, F1_, F3_, centers_,
      radii_, out_;
  cl::Kernel k_rows_, k_finish_, k_nodes_;
};

class OpenCLBackend final : public ComputeBackend {
 public:
  explicit OpenCLBackend(std::shared_ptr<Device> d, std::string build)
      : d_(std::move(d)), build_(std::move(build)) {}
  std::string name() const override { return "opencl (" + d_->label + ")"; }
  std::unique_ptr<EnergyKernels> energy_kernels(const DeformationEnergy& energy) const override {
    return std::make_unique<OpenCLEnergyKernels>(d_, energy);
  }
  std::unique_ptr<CertifierKernels> certifier_kernels(const CertifierData& data) const override {
    return std::make_unique<OpenCLCertifierKernels>(d_, data);
  }
  const std::string& build_message() const { return build_; }

 private:
  std::shared_ptr<Device> d_;
  std::string build_;
};

}  // namespace

std::vector<OpenCLDeviceInfo> opencl_devices(std::string* why) {
  std::vector<OpenCLDeviceInfo> out;
  try {
    std::vector<cl::Platform> platforms;
    cl::Platform::get(&platforms);
    for (cl::Platform& p : platforms) {
      std::vector<cl::Device> devices;
      try {
        p.getDevices(CL_DEVICE_TYPE_ALL, &devices);
      } catch (const cl::Error&) {
        continue;  // a platform without devices
      }
      for (cl::Device& d : devices) {
        OpenCLDeviceInfo info;
        info.platform = trim(p.getInfo<CL_PLATFORM_NAME>());
        info.name = trim(d.getInfo<CL_DEVICE_NAME>());
        info.version = trim(d.getInfo<CL_DEVICE_VERSION>());
        info.driver = trim(d.getInfo<CL_DRIVER_VERSION>());
        info.type = type_name(d.getInfo<CL_DEVICE_TYPE>());
        info.fp64 = has_fp64(d);
        info.global_mem = d.getInfo<CL_DEVICE_GLOBAL_MEM_SIZE>();
        info.max_alloc = d.getInfo<CL_DEVICE_MAX_MEM_ALLOC_SIZE>();
        info.compute_units = d.getInfo<CL_DEVICE_MAX_COMPUTE_UNITS>();
        out.push_back(info);
      }
    }
    if (out.empty() && why)
      *why = "no OpenCL platform or device found (is an ICD such as pocl-opencl-icd installed?)";
  } catch (const cl::Error& e) {
    if (why) *why = std::string("no OpenCL platform (") + cl_error_name(e.err()) + ")";
    out.clear();
  }
  return out;
}

std::string opencl_device_filter_from_env() {
  const char* f = std::getenv("LIDEF_OPENCL_DEVICE");
  return f ? std::string(f) : std::string();
}

OpenCLOptions opencl_options(const DeformParams& params) {
  OpenCLOptions o;
  o.device = params.opencl_device;
  o.gpu_layout = params.opencl_gpu_layout;
  o.break_kernels = params.test_break_kernels;
  o.max_alloc = static_cast<unsigned long long>(params.test_opencl_max_alloc);
  return o;
}

std::shared_ptr<const ComputeBackend> make_opencl_backend(const OpenCLOptions& options,
                                                          const std::string& cache_dir) {
  const std::string& filter = options.device;
  std::vector<cl::Platform> platforms;
  try {
    cl::Platform::get(&platforms);
  } catch (const cl::Error& e) {
    throw OpenCLError(std::string("OpenCL: no platform available (") + cl_error_name(e.err()) +
                      "); install an ICD (pocl-opencl-icd for the CPU, or the GPU vendor's driver)");
  }
  struct Candidate {
    cl::Platform p;
    cl::Device d;
    std::string label;
    bool gpu;
  };
  std::vector<Candidate> all, usable;
  for (cl::Platform& p : platforms) {
    std::vector<cl::Device> devices;
    try {
      p.getDevices(CL_DEVICE_TYPE_ALL, &devices);
    } catch (const cl::Error&) {
      continue;
    }
    for (cl::Device& d : devices) {
      Candidate c{p, d, trim(d.getInfo<CL_DEVICE_NAME>()) + " (" + trim(p.getInfo<CL_PLATFORM_NAME>()) + ")",
                  (d.getInfo<CL_DEVICE_TYPE>() & CL_DEVICE_TYPE_GPU) != 0};
      if (!filter.empty() && lower(c.label).find(lower(filter)) == std::string::npos) continue;
      all.push_back(c);
      if (has_fp64(d)) usable.push_back(c);
    }
  }
  if (all.empty())
    throw OpenCLError(filter.empty() ? std::string("OpenCL: no device found")
                                     : "OpenCL: no device matches opencl_device '" + filter + "'");
  if (usable.empty())
    throw OpenCLError("OpenCL (" + all.front().label +
                      "): the device has no double precision (cl_khr_fp64), which the certificate needs");
  std::stable_sort(usable.begin(), usable.end(),
                   [](const Candidate& a, const Candidate& b) { return a.gpu && !b.gpu; });
  const Candidate& c = usable.front();
  auto d = std::make_shared<Device>();
  d->platform = c.p;
  d->device = c.d;
  d->label = c.label;
  std::string how;
  guarded(d->label, "creating the context", [&] {
    d->context = cl::Context(d->device);
    d->queue = cl::CommandQueue(d->context, d->device);
    d->max_group = d->device.getInfo<CL_DEVICE_MAX_WORK_GROUP_SIZE>();
    d->cpu_device = (d->device.getInfo<CL_DEVICE_TYPE>() & CL_DEVICE_TYPE_CPU) != 0 && !options.gpu_layout;
    d->max_alloc = d->device.getInfo<CL_DEVICE_MAX_MEM_ALLOC_SIZE>();
    // Test hook (parameter test_opencl_max_alloc): pretend the device allows smaller buffers.
    if (options.max_alloc > 0) d->max_alloc = std::min<unsigned long long>(d->max_alloc, options.max_alloc);
    d->global_mem = d->device.getInfo<CL_DEVICE_GLOBAL_MEM_SIZE>();
    d->program = build_program(*d, cache_dir.empty() ? std::string() : cache_dir + "/opencl",
                               options.break_kernels, &how);
    return 0;
  });
  return std::make_shared<OpenCLBackend>(d, how);
}

std::shared_ptr<const ComputeBackend> select_backend(const DeformParams& params, const std::string& cache_dir,
                                                     std::string* message) {
  auto say = [&](const std::string& s) {
    if (message) *message = s;
  };
  if (params.backend == BackendKind::kCpu) {
    say("backend: cpu");
    return cpu_backend();
  }
  try {
    auto b = make_opencl_backend(opencl_options(params), cache_dir);
    say("backend: " + b->name() + "; " + static_cast<const OpenCLBackend&>(*b).build_message());
    return b;
  } catch (const OpenCLError& e) {
    if (params.backend == BackendKind::kOpenCL) throw;
    say(std::string("backend: cpu (auto: no usable OpenCL device: ") + e.what() + ")");
    return cpu_backend();
  }
}

BackendFactory opencl_backend_factory(const std::string& cache_dir) {
  return [cache_dir](const DeformParams& params, std::string* message) {
    return select_backend(params, cache_dir, message);
  };
}

}  // namespace lidef
