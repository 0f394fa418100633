// Settings have one source of truth: each default is one member initialiser, the presets and the
// ICPs derived from them are named functions, each enum has one table of names, and `map`'s
// options bind every setting, record every value for report.json, and print their defaults from
// the settings.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <set>
#include <string>

#include "minemap/cli/cli.hpp"
#include "minemap/cli/exit_codes.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

TEST(Settings, EachSharedDefaultHasOneDefinition) {
  // The 25 cm pair bound and the 250 pairs: ICP's and the mapping's start from one value each.
  EXPECT_EQ(IcpSettings{}.max_pair_dist_cm, PairingSettings{}.max_pair_dist_cm);
  EXPECT_EQ(MappingSettings{}.min_overlap_pairs, IcpTermination{}.min_pairs);
  // MappingSettings{} is the default preset, with its ICP.
  EXPECT_EQ(MappingSettings{}, MappingSettings::preset(Preset::kDefault));
  EXPECT_EQ(MappingSettings{}.icp, MappingSettings::default_icp());
  EXPECT_EQ(MappingSettings::preset(Preset::kSimultaneous), MappingSettings::simultaneous());
  EXPECT_EQ(MappingSettings::preset(Preset::kPaper), MappingSettings::paper());
  EXPECT_EQ(MappingSettings::paper().icp, IcpSettings::paper());
  EXPECT_EQ(MappingSettings::simultaneous().icp, MappingSettings::simultaneous_icp());
  for (const Preset preset : {Preset::kDefault, Preset::kSimultaneous, Preset::kPaper}) {
    EXPECT_NO_THROW(MappingSettings::preset(preset).validate()) << to_string(preset);
  }
}

TEST(Settings, TheDerivedIcpsAreTheMappingIcpWithTheirOwnChanges) {
  MappingSettings settings;
  // pairwise_icp(): a pair that passes the overlap test can be registered.
  settings.min_overlap_pairs = 100;
  EXPECT_EQ(settings.pairwise_icp().termination.min_pairs, 100);
  settings.icp.termination.min_pairs = 50;
  EXPECT_EQ(settings.pairwise_icp().termination.min_pairs, 50);
  IcpSettings expected = settings.icp;
  EXPECT_EQ(settings.pairwise_icp(), expected);
  // relaxation_icp(): the pairwise one, converged at the relaxation's own steps where they are set.
  expected.termination.min_translation_step_cm = settings.relaxation_min_step_cm;
  expected.termination.min_rotation_step_deg = settings.relaxation_min_step_deg;
  EXPECT_EQ(settings.relaxation_icp(), expected);
  const MappingSettings paper = MappingSettings::paper();
  EXPECT_EQ(paper.relaxation_icp(), paper.pairwise_icp());  // 0: ICP's own thresholds
}

template <typename Enum, std::size_t N>
void expect_round_trips(const std::array<EnumName<Enum>, N>& table, Enum (*parse)(const std::string&)) {
  std::set<std::string> names;
  for (const auto& [value, name] : table) {
    EXPECT_EQ(parse(name), value) << name;
    EXPECT_STREQ(to_string(value), name);
    names.insert(name);
  }
  EXPECT_EQ(names.size(), N);  // no name twice
  try {
    parse("nonsense");
    ADD_FAILURE() << "parsed 'nonsense'";
  } catch (const std::invalid_argument& e) {
    for (const std::string& name : names) EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
  }
}

TEST(Names, EveryEnumParsesItsOwnNamesAndListsThemWhenNot) {
  expect_round_trips(kMatchingModeNames, parse_matching_mode);
  expect_round_trips(kReductionNames, parse_reduction);
  expect_round_trips(kPresetNames, parse_preset);
  expect_round_trips(kSearchMethodNames, parse_search_method);
  expect_round_trips(kBackendNames, parse_backend);
  expect_round_trips(kMotionModelNames, parse_motion_model);
  expect_round_trips(kDeskewModeNames, parse_deskew_mode);
  EXPECT_EQ(parse_search_method("exact"), SearchMethod::kExact);  // the long names too
  EXPECT_EQ(parse_search_method("bruteforce"), SearchMethod::kBruteForce);
  EXPECT_EQ(name_in(kExitCodeNames, ExitCode::kDoubtfulMap), std::string("doubtful_map"));
  EXPECT_EQ(value_named(kExitCodeNames, "interrupted"), ExitCode::kInterrupted);
}

std::string key_of(std::string name) {
  name = name.substr(2);
  std::replace(name.begin(), name.end(), '-', '_');
  return name;
}

TEST(CommandLine, EveryOptionIsRecordedWithItsValue) {
  const cli::MapCommand command =
      cli::parse_map_options({"--voxel-cm", "16", "--no-retry", "--retry-bound-factors", "2,8", "--mode", "pairwise",
                              "--threads", "1", "--plain-icp"});
  EXPECT_EQ(command.settings.voxel_cm, 16.0f);
  EXPECT_TRUE(command.settings.retry_bound_factors.empty());  // --no-retry, applied after parsing
  EXPECT_FALSE(command.settings.icp.accelerate);
  std::map<std::string, RecordedSetting> recorded;
  for (const RecordedSetting& setting : command.recorded) EXPECT_TRUE(recorded.emplace(setting.name, setting).second);
  const std::vector<cli::OptionInfo> options = cli::map_options();
  EXPECT_EQ(recorded.size(), options.size());
  for (const cli::OptionInfo& option : options) EXPECT_TRUE(recorded.count(key_of(option.name))) << option.name;
  EXPECT_EQ(recorded.at("voxel_cm").value, "16");
  EXPECT_EQ(recorded.at("model_voxel_cm").value, "10");  // not given: the default, shortest form
  EXPECT_EQ(recorded.at("refine_fraction").value, "0.3");
  EXPECT_EQ(recorded.at("no_retry").value, "true");
  EXPECT_EQ(recorded.at("retry_bound_factors").value, "2,8");  // the option as given
  EXPECT_EQ(recorded.at("mode").value, "pairwise");
  EXPECT_EQ(recorded.at("unit").value, "");  // not given, no default
  // Where and how it runs: apart, as report.json's run_options.
  EXPECT_FALSE(recorded.at("threads").changes_poses);
  EXPECT_FALSE(recorded.at("backend").changes_poses);
  EXPECT_TRUE(recorded.at("voxel_cm").changes_poses);
}

// A perturbed value for an option whose default is `text` (valid for every option below).
std::string perturbed(const std::string& text) {
  if (text.find(',') != std::string::npos || text.front() == '[') return "3";
  const double value = std::stod(text);
  if (text.find('.') == std::string::npos && value == static_cast<long>(value)) return std::to_string(long(value) + 2);
  return std::to_string(value == 0.0 ? 0.5 : value * 1.5);
}

TEST(CommandLine, EveryMappingOptionChangesTheSettings) {
  // Each option outside the input and run groups is bound to a field of MappingSettings: changed,
  // it changes the settings map_survey is handed (or, for a choice, names another value).
  const MappingSettings defaults;
  const std::set<std::string> not_mapping = {"--threads", "--held-clouds-mb", "--opencl-device", "--backend", "--quiet",
                                             "--accept-doubtful", "--write-unregistered", "--unit",
                                             "--points-per-slice", "--no-slice-detection", "--initial-poses",
                                             "--reference-poses", "--right-handed-to-3dtk", "--preset", "--control"};
  std::size_t checked = 0;
  for (const cli::OptionInfo& option : cli::map_options()) {
    if (not_mapping.count(option.name)) continue;
    std::vector<std::string> args{option.name};
    if (!option.flag) {
      const std::string& d = option.default_value;
      if (option.name == "--mode") args.push_back("pairwise");
      else if (option.name == "--reduction") args.push_back("slices");
      else if (option.name == "--search") args.push_back("kd");
      else if (option.name == "--deskew") args.push_back("off");
      else if (option.name == "--motion-model") args.push_back("constant-velocity");
      else if (option.name == "--refine-search") args.push_back("exact");
      else args.push_back(perturbed(d.front() == '[' ? d.substr(1) : d));
    }
    SCOPED_TRACE(args.back());
    cli::MapCommand command;
    ASSERT_NO_THROW(command = cli::parse_map_options(args)) << option.name;
    EXPECT_FALSE(command.settings == defaults) << option.name << " changed nothing";
    ++checked;
  }
  EXPECT_GT(checked, 50u);
}

TEST(CommandLine, HelpTextsPrintTheirDefaultsFromTheSettings) {
  std::map<std::string, std::string> help;
  for (const cli::OptionInfo& option : cli::map_options()) help[option.name] = option.help;
  EXPECT_NE(help["--no-filter"].find("every 3rd slice"), std::string::npos) << help["--no-filter"];
  EXPECT_NE(help["--no-retry"].find("4x and 16x"), std::string::npos) << help["--no-retry"];
  EXPECT_NE(help["--no-loop-closing"].find("12+ scans"), std::string::npos) << help["--no-loop-closing"];
  // A preset that changes a default changes the option's default with it.
  for (const cli::OptionInfo& option : cli::map_options(Preset::kPaper)) {
    if (option.name == "--refine-fraction") {
      EXPECT_EQ(option.default_value, "0");
    }
    if (option.name == "--reduction") {
      EXPECT_EQ(option.default_value, "slices");
    }
  }
}

}  // namespace
}  // namespace minemap
