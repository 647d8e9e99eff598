#pragma once
// CPU-time clocks for benchmarks and frame-time logs (POSIX). CPU time is what a step costs a
// core; on a shared, loaded machine it is far steadier than wall time, which other processes
// inflate.
//   const auto t0 = ave::ThreadCpuClock::now();  ...  ave::ThreadCpuClock::now() - t0
//   const double cpu0 = ave::ProcessCpuSeconds();
#include <sys/resource.h>
#include <time.h>

#include <chrono>

namespace ave {

// CPU time of the calling thread (other threads and processes do not count), through the
// std::chrono clock interface.
struct ThreadCpuClock {
  using duration = std::chrono::nanoseconds;
  using rep = duration::rep;
  using period = duration::period;
  using time_point = std::chrono::time_point<ThreadCpuClock>;
  static constexpr bool is_steady = true;
  static time_point now() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return time_point(duration(static_cast<rep>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec));
  }
};

// CPU seconds of the calling thread.
inline double ThreadCpuSeconds() {
  return std::chrono::duration<double>(ThreadCpuClock::now().time_since_epoch()).count();
}

// CPU seconds (user + system) of the whole process, every thread included (a renderer's worker
// threads, a client's receiving thread).
inline double ProcessCpuSeconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
}

}  // namespace ave
