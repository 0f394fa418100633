#pragma once
// Internal to the command line. `map`'s (and `watch`'s) options, declared once, by stage, in CLI11
// option groups that --help shows as sections; each is bound to its MappingSettings or MapOptions
// field, so the struct's member initialiser (after the preset) is the default --help prints. The
// groups marked as not changing the poses replace a hand-kept list: a resumed watch compares the
// options outside them. The declarations also record every option's value for report.json.
//
// Thread-safety: a MapOptionTable refers to the MapCommand it binds; one thread.
#include <CLI/CLI.hpp>

#include <functional>
#include <string>
#include <vector>

#include "minemap/cli/cli.hpp"

namespace minemap::cli {

/// The options of `map` bound to `target` (whose settings hold the preset's values already).
/// Alive as long as the CLI::App it declared them in.
class MapOptionTable {
 public:
  MapOptionTable(CLI::App& app, MapCommand& target);
  /// Every option's value now (call after parsing), for report.json.
  std::vector<RecordedSetting> record() const;

 private:
  template <typename T>
  CLI::Option* number(const char* group, const std::string& name, T& value, const std::string& help);
  CLI::Option* numbers(const char* group, const std::string& name, std::vector<float>& value, const std::string& help);
  CLI::Option* flag(const char* group, const std::string& name, bool& value, const std::string& help);
  template <typename Enum, std::size_t N>
  CLI::Option* choice(const char* group, const std::string& name, Enum& value,
                      const std::array<EnumName<Enum>, N>& names, Enum (*parse)(const std::string&),
                      const std::string& help);
  template <typename Text>
  CLI::Option* text(const char* group, const std::string& name, Text& value, const std::string& help);

  void declare_input(MapOptions& map);
  void declare_reduction(MapOptions& map, MappingSettings& mapping);
  void declare_matching(MapOptions& map, MappingSettings& mapping);
  void declare_relaxation(MappingSettings& mapping);
  void declare_health(MapOptions& map, MappingSettings& mapping);
  void declare_loops(MapOptions& map, MappingSettings& mapping);
  void declare_run(MapOptions& map);

  CLI::App& app_;
  std::vector<std::function<RecordedSetting()>> recorders_;
};

/// Option groups (--help's sections); the last two do not change the poses.
namespace groups {
inline constexpr const char* kInput = "Input";
inline constexpr const char* kReduction = "Reduction (paper IV.C)";
inline constexpr const char* kMatching = "Matching and ICP (paper IV.A, IV.B)";
inline constexpr const char* kRelaxation = "Relaxation (--mode simultaneous, paper IV.B step 3)";
inline constexpr const char* kHealth = "Health check and retries";
inline constexpr const char* kLoops = "Loop closing";
inline constexpr const char* kRun = "Run (does not change the poses)";
inline constexpr const char* kWatch = "Watch (does not change the poses)";
}  // namespace groups
/// Whether options of `group` leave the poses as they are (where and how a run runs, what it prints).
bool changes_no_pose(const std::string& group);

/// --threads and --opencl-device, also accepted before the subcommand (process-wide options).
void add_process_options(CLI::App& app, MapOptions& options);

/// The preset named by `--preset` anywhere in `args` (the default when absent or malformed: the
/// parser then reports the malformed one).
Preset preset_argument(const std::vector<std::string>& args);

/// The flags that switch parts of the settings off, applied once parsing is done; then validated.
void finish_settings(MapCommand& command);

/// The options of a parsed `watch` that change what is computed, one "name=value" per line, sorted
/// (CLI11's config text of what was given, without the groups that change no pose): a resume with
/// others would not continue the same run.
std::string mapping_options_text(const CLI::App& command);

}  // namespace minemap::cli
