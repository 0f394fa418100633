// The `minemap` command line (cli.hpp): the subcommands wired, and the one table from what went
// wrong to the exit code (cli/exit_codes.hpp; the bad-input cases in docs/bad-input.md).
#include <iostream>
#include <optional>

#include "minemap/cli/cli.hpp"
#include "minemap/cli/commands.hpp"
#include "minemap/cli/exit_codes.hpp"
#include "minemap/cli/signals.hpp"
#include "minemap/core/atomic_file.hpp"
#include "minemap/core/error.hpp"

namespace minemap::cli {
namespace {

int code(ExitCode exit) { return static_cast<int>(exit); }

/// Runs `command`, turning what it throws into the exit code and a message on stderr.
template <typename Command>
int with_exit_codes(Command&& command, const fs::path& out_on_interrupt) {
  try {
    return command();
  } catch (const signals::Interrupted&) {
    if (!out_on_interrupt.empty()) remove_stale_temp_files(out_on_interrupt);
    std::cerr << "minemap: interrupted; outputs already written are complete, nothing was half-written\n";
    return code(ExitCode::kInterrupted);
  } catch (const InputError& e) {
    // Thrown while reading, before the output folder is touched: it is left as it was.
    std::cerr << "minemap: " << e.what() << "\n";
    return code(exit_code_for(e.problem()));
  } catch (const OutputError& e) {
    std::cerr << "minemap: " << e.what() << "\n";
    return code(ExitCode::kOutputError);
  } catch (const BackendError& e) {
    std::cerr << "minemap: " << e.what() << "\n";
    return code(ExitCode::kBackendUnavailable);
  } catch (const std::invalid_argument& e) {
    std::cerr << "minemap: " << e.what() << "\n";
    return code(ExitCode::kUsage);
  } catch (const std::exception& e) {
    std::cerr << "minemap: error: " << e.what() << "\n";
    return code(ExitCode::kInternal);
  }
}

/// The command line as given, program first (report.json's "command_line").
std::vector<std::string> command_line_of(const std::vector<std::string>& args) {
  std::vector<std::string> line{"minemap"};
  line.insert(line.end(), args.begin(), args.end());
  return line;
}

}  // namespace

int run(const std::vector<std::string>& args, const Hooks& hooks) {
  CLI::App app{"minemap: 6D SLAM for 3D laser scans of mines (Nuechter et al.)"};
  app.name("minemap");
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("minemap ") + version());
  // Process-wide options: accepted before the subcommand and after it (where users type them), and
  // listed in each subcommand's --help; both places write the same variables for `map`, and are
  // copied into `watch`'s below.
  const Preset preset = preset_argument(args);
  MapCommand map;
  map.options.preset = preset;
  map.settings = MappingSettings::preset(preset);
  add_process_options(app, map.options);

  SimulateOptions sim;
  CLI::App* simulate = add_simulate_command(app, sim, map.options);
  MapCommand watch = map;  // its own copy: CLI11 binds each subcommand's options to their targets
  const MapSubcommand map_command = add_map_command(app, map);
  WatchOptions watch_options;
  const MapSubcommand watch_command = add_watch_command(app, watch, watch_options);
  ExportOptions export_options;
  CLI::App* export_command = add_export_command(app, export_options, map.options);

  try {
    std::vector<std::string> reversed(args.rbegin(), args.rend());
    app.parse(reversed);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : code(ExitCode::kUsage);
  }
  // `map`, `watch` and `export` stop at a scan boundary on Ctrl-C (SIGINT) or SIGTERM; simulate
  // dies as usual.
  std::optional<signals::InterruptHandlers> handlers;
  if (*map_command.app || *watch_command.app || *export_command) handlers.emplace();
  if (*export_command) {
    return with_exit_codes([&] { return with_threads(map.options, [&] { return run_export(export_options, hooks); }); },
                           {});
  }
  if (*simulate) return with_exit_codes([&] { return with_threads(map.options, [&] { return run_simulate(sim); }); }, {});
  if (*watch_command.app) {
    return with_exit_codes(
        [&] {
          // Process-wide options given before the subcommand.
          if (watch.options.threads == 0) watch.options.threads = map.options.threads;
          if (watch.options.opencl_device.empty()) watch.options.opencl_device = map.options.opencl_device;
          watch.recorded = watch_command.options->record();
          watch.command_line = command_line_of(args);
          finish_settings(watch);
          return run_watch(watch, watch_options, mapping_options_text(*watch_command.app), hooks);
        },
        {});
  }
  return with_exit_codes(
      [&] {
        map.recorded = map_command.options->record();
        map.command_line = command_line_of(args);
        finish_settings(map);
        return run_map(map, hooks);
      },
      map.options.out);
}

}  // namespace minemap::cli
