#pragma once
// Internal (not installed). What every stage of a mapping run is handed besides its data: the
// caller's progress and stop callbacks, and the stage clocks (MappingResult::times).
//
// Thread-safety: one thread at a time, the one running the mapping.
#include <chrono>
#include <cstddef>
#include <string>
#include <type_traits>
#include <utility>

#include "minemap/slam/mapping_result.hpp"
#include "minemap/slam/progress.hpp"

namespace minemap::detail {

class RunControl {
 public:
  RunControl(ProgressCallback progress = {}, StopRequested stop = {})
      : progress_(std::move(progress)), stop_(std::move(stop)) {}

  /// The scans the run expects, for progress (done of total).
  void expect(std::size_t total) { total_ = total; }
  void report(std::size_t done, const std::string& phase) const {
    if (progress_) progress_(done, total_, phase);
  }
  bool stop_requested() const { return stop_ && stop_(); }

  /// Runs `work` and adds its wall-clock seconds to `stage` of times().
  template <typename Work>
  decltype(auto) timed(double StageTimes::*stage, Work&& work) {
    const Stopwatch clock;
    if constexpr (std::is_void_v<decltype(work())>) {
      work();
      times_.*stage += clock.seconds();
    } else {
      decltype(auto) result = work();
      times_.*stage += clock.seconds();
      return result;
    }
  }
  StageTimes& times() { return times_; }
  const StageTimes& times() const { return times_; }

  /// Seconds since it was made.
  class Stopwatch {
   public:
    double seconds() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }

   private:
    using Clock = std::chrono::steady_clock;
    Clock::time_point start_ = Clock::now();
  };

 private:
  ProgressCallback progress_;
  StopRequested stop_;
  std::size_t total_ = 0;
  StageTimes times_;
};

}  // namespace minemap::detail
