// `minemap map`: read a survey, map it, write the map; the exit code says how far it can be trusted.
#include <cstdio>

#include "minemap/cli/commands.hpp"
#include "minemap/cli/console.hpp"
#include "minemap/cli/exit_codes.hpp"
#include "minemap/cli/signals.hpp"

namespace minemap::cli {

MapSubcommand add_map_command(CLI::App& app, MapCommand& command) {
  MapSubcommand map;
  map.app = app.add_subcommand("map", "Register a survey into one consistent map");
  map.app->add_option("survey", command.options.survey,
                      "Survey folder (uos, pcd, ply or kitti layout; LAS/LAZ and E57 through the Python package)")
      ->required()
      ->group(groups::kRun);
  map.app->add_option("--out", command.options.out, "Output folder")->required()->group(groups::kRun);
  map.options = std::make_unique<MapOptionTable>(*map.app, command);
  return map;
}

int run_map(const MapCommand& command, const Hooks& hooks) {
  const MapOptions& options = command.options;
  begin_log(command.command_line);
  ProgressBar bar(!options.quiet);
  // Ctrl-C or SIGTERM stops the run between scans (and between relaxation matches); what was
  // matched by then is written below, marked partial, and the exit code is 130.
  MapRun run = run_map_command(
      command, [&](std::size_t done, std::size_t total, const std::string& phase) { bar(done, total, phase); },
      [&] { return signals::interrupted() || (hooks.stop_requested && hooks.stop_requested()); });
  bar.finish();
  const MappingResult& result = run.result;
  if (!options.quiet) {
    for (const auto& note : result.notes) say(stdout, "note: %s\n", note.c_str());
  }
  const Verdict verdict = judge_run(result, sources_of(run.survey));
  if (!write_despite(verdict, options)) return static_cast<int>(ExitCode::kRegistrationFailed);
  write_outputs(command, run, hooks.extra_outputs);
  if (result.interrupted) {
    say(stderr, "minemap: interrupted: wrote the %zu of %zu scans matched so far to %s (report.json: partial)\n",
        result.scans.size(), run.survey_scans, options.out.c_str());
    write_log(options.out, version());
    return static_cast<int>(ExitCode::kInterrupted);
  }
  if (signals::interrupted()) throw signals::Interrupted{};  // arrived while writing: the outputs are complete
  print_loops(options, result);
  print_control(options, result);
  if (!options.quiet) {
    // The first pass matches each new scan against the previous one (pairwise, simultaneous) or
    // against the metascan (incremental): name it as it ran.
    const char* first_pass = command.settings.mode == MatchingMode::kIncremental ? "incremental" : "pairwise";
    say(stdout, "matched %zu scans: %d ICP iterations %s, %d in %d relaxation matches; %.2f s filter, "
                "%.2f s trees, %.2f s %s, %.2f s relaxation\n",
                result.scans.size(), result.step1_icp_iterations, first_pass, result.step3_icp_iterations,
                result.relaxation_matches, result.times.filter_s, result.times.tree_build_s, result.times.pairwise_s,
                first_pass, result.times.relaxation_s);
    print_summary(result);
    print_truth(run);
    std::string extra;
    for (const std::string& name : hooks.extra_output_names) extra += ", " + name;
    say(stdout, "wrote %s (frames, poses, trajectory.tum, map.ply%s, report.json, top.png, side.png, map.html, "
        "minemap.log)\n", options.out.c_str(), extra.c_str());
  }
  const int code = exit_code_of(verdict, options, result.scans.size());
  write_log(options.out, version());
  return code;
}

}  // namespace minemap::cli
