#pragma once
// What a mapping run tells its caller while it runs, and how the caller stops it.
#include <cstddef>
#include <functional>
#include <string>

namespace minemap {

/// Reports progress: scans done of total, and a short phase name: the mode's name while matching,
/// then "loop matches" (the returns to known places looked for and matched, up to that scan),
/// "pose graph" (each scan's step weighed for the pose graph: a loop closed, or a tie to control)
/// and "judging" (each scan judged again after a loop's relaxation).
/// Called from the thread that runs the mapping.
using ProgressCallback = std::function<void(std::size_t done, std::size_t total, const std::string& phase)>;
/// Asked between scans (and between relaxation and loop matches): true stops the run, which returns
/// what it finished (MappingResult::interrupted). Called from the thread that runs the mapping.
using StopRequested = std::function<bool()>;

}  // namespace minemap
