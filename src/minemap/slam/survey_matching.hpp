#pragma once
// The many-scan matcher's public face in one include (paper, section IV.B). Each part is a room of
// its own; docs/architecture.md walks a survey through them.
//   mapping_settings.hpp  modes, reduction, ICP, relaxation, loops, health; presets; validation
//   mapping_result.hpp    what a run hands back: outcomes per scan, loops, times, Table I's counters
//   map_survey.hpp        map_survey (whole survey, CPU fallback) and LiveMapper (scan by scan)
//   pose_errors.hpp       errors against reference poses
//   pose_graph.hpp        the global relaxation of the scan graph (loops)
#include "minemap/slam/map_survey.hpp"
#include "minemap/slam/mapping_result.hpp"
#include "minemap/slam/mapping_settings.hpp"
#include "minemap/slam/pose_errors.hpp"
#include "minemap/slam/pose_graph.hpp"
