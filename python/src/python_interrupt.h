// Ctrl-C for the Python module's long calls. They run with the GIL released; Python's SIGINT handler only
// marks the signal, and the interpreter acts on it when someone calls PyErr_CheckSignals on the main thread.
// The library's progress callbacks (preprocessing chunks, Newton iterations, continuation stages) do that on
// the calling thread, at most every 20 ms, with the GIL taken back for the check; a raised KeyboardInterrupt
// sets the library's cancel flag (PrecomputeSetup::cancel, the solve's stop flag), the call stops at its next
// unit of work with the last certified map kept, and the KeyboardInterrupt is raised to the caller.
#pragma once
#include <pybind11/pybind11.h>

#include <atomic>
#include <chrono>
#include <exception>
#include <thread>

#include "lidef/deform.h"
#include "lidef/errors.h"
#include "lidef/projected_newton.h"

namespace lidef::python {

namespace py = pybind11;

class Interrupt {
 public:
  Interrupt() : caller_(std::this_thread::get_id()) {}
  Interrupt(const Interrupt&) = delete;
  Interrupt& operator=(const Interrupt&) = delete;

  void attach(DeformOptions& o) {
    o.stop = &stop_;
    o.progress = [this](const std::string&, double) { poll(); };
    o.on_iteration = [this](const IterationRecord&) { return poll(); };
    o.on_stage = [this](const std::string&) { poll(); };
  }
  void attach(PrecomputeSetup& s) {
    s.cancel = &stop_;
    s.progress = [this](const std::string&, double) { poll(); };
  }

  // Runs `work` with the GIL released (called with it held). A signal's exception seen meanwhile is raised
  // here (after `work` stopped); otherwise `work`'s own exceptions propagate.
  template <class F>
  void run(F&& work) {
    std::exception_ptr failure;
    {
      py::gil_scoped_release release;
      try {
        work();
      } catch (...) {
        failure = std::current_exception();
      }
    }
    if (signalled_) throw py::error_already_set();  // the KeyboardInterrupt PyErr_CheckSignals set
    if (failure) std::rethrow_exception(failure);
  }

  // false once the call should stop. Checks Python's signals on the calling thread only (a handler runs on
  // the main thread; PyErr_CheckSignals elsewhere does nothing).
  bool poll() {
    if (stop_.load()) return false;
    if (std::this_thread::get_id() != caller_) return true;
    const auto now = std::chrono::steady_clock::now();
    if (now - last_ < std::chrono::milliseconds(20)) return true;
    last_ = now;
    py::gil_scoped_acquire acquire;
    if (PyErr_CheckSignals() != 0) {
      signalled_ = true;
      stop_.store(true);
      return false;
    }
    return true;
  }

 private:
  std::thread::id caller_;
  std::atomic<bool> stop_{false};
  bool signalled_ = false;  // touched on the calling thread only
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace lidef::python
