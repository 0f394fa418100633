#pragma once
// Internal to the command line. OUT/watch.json, the checkpoint of `minemap watch`: what a restarted
// watch resumes from without matching again what it matched: each scan's outcome (poses to the bit,
// frames, match, health), the relaxation queue and the run's counters, and the options it ran with.
// Doubles are written so that they read back exactly (nlohmann's shortest round-trip form).
#include <filesystem>
#include <string>
#include <vector>

#include "minemap/slam/survey_matching.hpp"

namespace minemap::cli {

struct WatchState {
  std::string options;  ///< the mapping options it ran with (a resume must use the same)
  bool finished = false;  ///< the outputs are the finished map (the state itself never is)
  std::vector<std::string> sources;  ///< each scan's file, for the check that the folder still holds it
  MappingResult result;   ///< outcomes (without their points) and counters, not finished
  std::vector<std::size_t> queue;
};

/// The state as JSON text. Thread-safety: reentrant.
std::string watch_state_json(const WatchState& state);

/// Reads a state written by watch_state_json; throws InputError naming the file on anything else.
WatchState read_watch_state(const std::filesystem::path& path);

}  // namespace minemap::cli
