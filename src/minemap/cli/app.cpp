// The `minemap` command line (cli.hpp): the subcommands wired, and the one table from what went
// wrong to the exit code (cli/exit_codes.hpp; the bad-input cases in docs/bad-input.md).
#include <algorithm>
#include <filesystem>
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
  } catch (const std::filesystem::filesystem_error& e) {
    // Reading throws InputError; what the filesystem refuses here is an output (a folder that
    // cannot be created, a full disk): exit 5, as docs/bad-input.md says.
    std::cerr << "minemap: cannot write " << e.path1().string() << ": " << e.code().message() << "\n";
    return code(ExitCode::kOutputError);
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

/// Levenshtein distance over bytes: small for a typo, a missing letter, one odd character.
std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t substituted = diagonal + (a[i - 1] == b[j - 1] ? 0 : 1);
      diagonal = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, substituted});
    }
  }
  return row[b.size()];
}

/// The nearest of `names` to `word`, when it is near enough to be what was meant (a prefix, as
/// --max-pair-dist for --max-pair-dist-cm, or a few edits away); empty otherwise.
std::string nearest(const std::string& word, const std::vector<std::string>& names) {
  std::string best;
  std::size_t best_distance = std::max<std::size_t>(2, word.size() / 3) + 1;
  for (const std::string& name : names) {
    const std::size_t distance = name.rfind(word, 0) == 0 ? 1 : edit_distance(word, name);
    if (distance < best_distance) {
      best = name;
      best_distance = distance;
    }
  }
  return best;
}

/// Names the word of the command line that is no subcommand or no option of the chosen one, with
/// the nearest real one, before CLI11 parses: its own messages for these ("A subcommand is
/// required", "--out is required" for a mistyped --out, extras listed in reverse) hide the word.
/// Empty when every word is known (CLI11 then judges values and requirements).
std::string unknown_word(CLI::App& app, const std::vector<std::string>& args) {
  std::vector<std::string> commands;
  for (const CLI::App* sub : app.get_subcommands({})) commands.push_back(sub->get_name());
  CLI::App* chosen = nullptr;
  for (const std::string& arg : args) {
    for (CLI::App* sub : app.get_subcommands({})) {
      if (arg == sub->get_name()) chosen = sub;
    }
    if (chosen != nullptr) break;
  }
  if (chosen == nullptr) {
    for (const std::string& arg : args) {
      if (arg.empty() || arg[0] == '-') continue;
      const std::string guess = nearest(arg, commands);
      if (!guess.empty()) return "unknown command '" + arg + "': did you mean '" + guess + "'? (minemap --help lists them)";
    }
    return {};
  }
  std::vector<std::string> options;
  for (const CLI::App* scope : {static_cast<const CLI::App*>(&app), static_cast<const CLI::App*>(chosen)}) {
    for (const CLI::Option* option : scope->get_options({})) {
      for (const std::string& name : option->get_lnames()) options.push_back(name);
    }
  }
  for (const std::string& arg : args) {
    if (arg == "--") break;
    if (arg.size() < 3 || arg.rfind("--", 0) != 0) continue;
    const std::string name = arg.substr(2, arg.find('=') == std::string::npos ? std::string::npos : arg.find('=') - 2);
    if (std::find(options.begin(), options.end(), name) != options.end()) continue;
    const std::string guess = nearest(name, options);
    return "unknown option --" + name + " for " + chosen->get_name() +
           (guess.empty() ? std::string() : ": did you mean --" + guess + "?") + " (minemap " + chosen->get_name() +
           " --help lists them)";
  }
  return {};
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

  if (const std::string word = unknown_word(app, args); !word.empty()) {
    std::cerr << "minemap: " << word << "\n";
    return code(ExitCode::kUsage);
  }
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
