// The one stopwatch of the project's timings (reports' seconds, benchmarks' milliseconds): wall-clock time on
// the monotonic clock, so that a change of the system time during a run cannot make a time negative.
#pragma once
#include <chrono>

namespace lidef {

using Clock = std::chrono::steady_clock;

// Seconds since t0 (a Clock::now() taken before).
inline double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}
// Milliseconds since t0.
inline double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

}  // namespace lidef
