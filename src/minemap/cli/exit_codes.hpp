#pragma once
// The `minemap` program's exit codes: a CLI matter, so they live with the CLI.
#include "minemap/core/error.hpp"
#include "minemap/core/name_table.hpp"

namespace minemap {

/// Process exit codes of the `minemap` program; each failure class has its own code so scripts that
/// reprocess surveys unattended can tell them apart. Codes 3 and 7..12 are input problems
/// (InputProblem, exit_code_for); every one of them is found before the output folder is touched.
/// docs/bad-input.md lists which case gets which code, per reader.
enum class ExitCode : int {
  kOk = 0,
  kInternal = 1,             ///< a bug or an unexpected exception
  kUsage = 2,                ///< bad command line
  kInputError = 3,           ///< malformed or unreadable input: bad syntax, binary garbage, a missing file
  kRegistrationFailed = 4,   ///< a scan could not be registered (no overlap, too few pairs, NaN); nothing is
                             ///< written unless --write-unregistered
  kOutputError = 5,          ///< the output folder could not be written
  kBackendUnavailable = 6,   ///< --backend opencl was asked for and no usable OpenCL device exists
  kTruncatedInput = 7,       ///< a file ends before the data its header or its last line promises
  kNonFiniteInput = 8,       ///< an infinite coordinate or pose value, or a scan whose points are all NaN
  kEmptyInput = 9,           ///< an empty file, a scan with fewer than 3 points, a folder without scans
  kInconsistentSurvey = 10,  ///< duplicate scans, a missing pose file, pose and scan counts that differ
  kCountBeyondLimits = 11,   ///< a header count beyond the limits (ReadSettings::max_points), checked before allocating
  kSuspiciousUnits = 12,     ///< the survey looks like metres read as cm: map it with --unit m (or --unit cm)
  kDoubtfulMap = 13,         ///< every scan registered, but a match failed the health check (registration/
                             ///< health.hpp): the outputs are written, the scans are named (console and
                             ///< report.json); --accept-doubtful makes it 0
  kInterrupted = 130,        ///< SIGINT: finished outputs are kept, temp files removed
};

/// Each code's name, for programs that run `minemap` (the Python package's batch runner reads it).
inline constexpr std::array<EnumName<ExitCode>, 15> kExitCodeNames{{
    {ExitCode::kOk, "ok"},
    {ExitCode::kInternal, "internal"},
    {ExitCode::kUsage, "usage"},
    {ExitCode::kInputError, "input_error"},
    {ExitCode::kRegistrationFailed, "registration_failed"},
    {ExitCode::kOutputError, "output_error"},
    {ExitCode::kBackendUnavailable, "backend_unavailable"},
    {ExitCode::kTruncatedInput, "truncated_input"},
    {ExitCode::kNonFiniteInput, "non_finite_input"},
    {ExitCode::kEmptyInput, "empty_input"},
    {ExitCode::kInconsistentSurvey, "inconsistent_survey"},
    {ExitCode::kCountBeyondLimits, "count_beyond_limits"},
    {ExitCode::kSuspiciousUnits, "suspicious_units"},
    {ExitCode::kDoubtfulMap, "doubtful_map"},
    {ExitCode::kInterrupted, "interrupted"},
}};

/// The exit code of the `minemap` program for an input problem.
constexpr ExitCode exit_code_for(InputProblem problem) {
  switch (problem) {
    case InputProblem::kMalformed: return ExitCode::kInputError;
    case InputProblem::kTruncated: return ExitCode::kTruncatedInput;
    case InputProblem::kNonFinite: return ExitCode::kNonFiniteInput;
    case InputProblem::kEmpty: return ExitCode::kEmptyInput;
    case InputProblem::kInconsistentSurvey: return ExitCode::kInconsistentSurvey;
    case InputProblem::kCountBeyondLimits: return ExitCode::kCountBeyondLimits;
    case InputProblem::kSuspiciousUnits: return ExitCode::kSuspiciousUnits;
  }
  return ExitCode::kInputError;
}

}  // namespace minemap
