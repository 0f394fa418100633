#include "minemap/slam/map_survey.hpp"

#include <stdexcept>

#include "minemap/backend/cpu_backend.hpp"
#include "minemap/slam/survey_matcher.hpp"

namespace minemap {

MappingResult map_survey(const std::vector<Scan>& scans, const MappingSettings& settings, ComputeBackend& backend,
                         const ProgressCallback& progress, const StopRequested& stop_requested) {
  settings.validate();
  if (scans.empty()) throw std::invalid_argument("the survey holds no scans");
  try {
    return detail::SurveyMatcher(settings, backend, {progress, stop_requested}).run(scans);
  } catch (const BackendError& e) {
    if (backend.name() == "cpu") throw;
    // The device failed mid-run: match everything again on the CPU, which gives the CPU's poses.
    const std::string failed = backend.name() == "opencl" ? "OpenCL" : backend.name();
    CpuBackend cpu;
    MappingResult result = detail::SurveyMatcher(settings, cpu, {progress, stop_requested}).run(scans);
    result.backend_note = "CPU backend (TBB), after the " + failed + " failure in the note";
    result.notes.insert(result.notes.begin(),
                        failed + " failed (" + e.what() + "); the survey was matched again on the CPU");
    return result;
  }
}

MappingResult map_survey_releasing_points(std::vector<Scan>& scans, const MappingSettings& settings,
                                          ComputeBackend& backend, const ProgressCallback& progress,
                                          const StopRequested& stop_requested) {
  if (backend.name() != "cpu") return map_survey(scans, settings, backend, progress, stop_requested);
  settings.validate();
  if (scans.empty()) throw std::invalid_argument("the survey holds no scans");
  return detail::SurveyMatcher(settings, backend, {progress, stop_requested}).run(scans, &scans);
}

PartwiseMapper::PartwiseMapper(const MappingSettings& settings, ComputeBackend& backend,
                               const ProgressCallback& progress, const StopRequested& stop_requested,
                               const MemoryBound& bound)
    : settings_(settings) {
  settings_.validate();
  matcher_ = std::make_unique<detail::SurveyMatcher>(settings_, backend, detail::RunControl{progress, stop_requested});
  if (bound.held_clouds_mb == 0) return;
  if (backend.name() != "cpu") {
    throw std::invalid_argument("a memory bound holds the CPU backend's clouds; the " + backend.name() +
                                " backend keeps its own on the device");
  }
  if (bound.spill_folder.empty()) throw std::invalid_argument("a memory bound needs a folder for its spill file");
  matcher_->bound_memory(bound.spill_folder, bound.held_clouds_mb * 1024 * 1024);
}
PartwiseMapper::~PartwiseMapper() = default;

bool PartwiseMapper::add(std::vector<Scan>& part, std::size_t total) {
  if (stopped_) return false;
  stopped_ = !matcher_->add_part(part, total);
  return !stopped_;
}

MappingResult PartwiseMapper::finish() {
  if (matcher_->size() == 0) throw std::invalid_argument("the survey holds no scans");
  if (!stopped_) matcher_->finish();
  return matcher_->result();
}

struct LiveMapper::Impl {
  Impl(const MappingSettings& settings_in, ComputeBackend& backend, StopRequested stop)
      : settings(settings_in), matcher(settings, backend, {{}, std::move(stop)}) {}
  MappingSettings settings;  // the matcher's own copy: it refers to it
  detail::SurveyMatcher matcher;
};

LiveMapper::LiveMapper(const MappingSettings& settings, ComputeBackend& backend, StopRequested stop_requested) {
  settings.validate();
  impl_ = std::make_unique<Impl>(settings, backend, std::move(stop_requested));
}
LiveMapper::~LiveMapper() = default;
void LiveMapper::add(const Scan& scan) { impl_->matcher.add(scan); }
void LiveMapper::restore(const Scan& scan, const ScanOutcome& outcome) { impl_->matcher.restore(scan, outcome); }
std::vector<std::size_t> LiveMapper::queue() const { return impl_->matcher.queue(); }
void LiveMapper::restore_queue(const std::vector<std::size_t>& queue) { impl_->matcher.restore_queue(queue); }
void LiveMapper::restore_counters(const MappingResult& saved) { impl_->matcher.restore_counters(saved); }
MappingResult LiveMapper::result() const { return impl_->matcher.result(); }
const ScanOutcome& LiveMapper::scan(std::size_t i) const { return impl_->matcher.scan(i); }
void LiveMapper::finish() { impl_->matcher.finish(); }
std::size_t LiveMapper::size() const { return impl_->matcher.size(); }

}  // namespace minemap
