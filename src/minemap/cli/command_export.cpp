// `minemap export OUT --to FILE`: the registered survey at full density (report/survey_export.hpp),
// streamed scan by scan into one file whose extension picks the format: PLY here; LAS/LAZ, COPC
// (.copc.laz) and E57 through the Python package's writer (Hooks::export_writer).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <sstream>

#include "minemap/cli/commands.hpp"
#include "minemap/cli/console.hpp"
#include "minemap/cli/exit_codes.hpp"
#include "minemap/cli/signals.hpp"

namespace minemap::cli {
namespace {

std::string lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return text;
}

bool ends_with(const std::string& text, const std::string& end) {
  return text.size() >= end.size() && text.compare(text.size() - end.size(), end.size(), end) == 0;
}

std::vector<std::string> names_of(const std::string& list) {
  std::vector<std::string> names;
  std::istringstream in(list);
  for (std::string name; std::getline(in, name, ',');) {
    if (!name.empty()) names.push_back(name);
  }
  return names;
}

}  // namespace

CLI::App* add_export_command(CLI::App& app, ExportOptions& options, MapOptions& process) {
  auto* command = app.add_subcommand(
      "export", "Write the registered survey at full density (every point, its attributes, its scan) to one file");
  command->footer(
      "OUT is the --out of a finished `minemap map` (or `watch`); the scans are read again, one at a time, from where\n"
      "its report.json says. FILE's extension picks the format: .ply here; .las, .laz, .copc.laz and .e57 through\n"
      "the Python package (python -m minemap export ...). The file appears whole or not at all.");
  command->add_option("out", options.out, "A map's output folder (its report.json)")->required();
  command->add_option("--to", options.to, "The file to write (.ply; .las .laz .copc.laz .e57 from Python)")->required();
  command->add_option("--voxel-cm", options.settings.voxel_cm,
                      "Thin each scan to its first point in each cube of this size (0 = every point)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  command->add_option("--scans", options.scans, "Only these scans, comma-separated (default: every registered scan)");
  command->add_option("--frame", options.frame,
                      "z-up: metres, right-handed, z up; survey: the survey's own frame and unit (3DTK's for uos)")
      ->check(CLI::IsMember(std::vector<std::string>{"z-up", "survey"}))
      ->capture_default_str();
  command->add_flag("--quiet", options.quiet, "Print nothing but errors");
  command->add_option("--threads", process.threads, "Worker threads (0 = all cores)")->group(groups::kRun);
  return command;
}

int run_export(const ExportOptions& options, const Hooks& hooks) {
  ExportSettings settings = options.settings;
  settings.frame = options.frame == "survey" ? ExportSettings::Frame::kSurvey : ExportSettings::Frame::kZUp;
  settings.scans = names_of(options.scans);
  const std::string name = lower(options.to.filename().string());
  const bool ply = ends_with(name, ".ply");
  const bool foreign = ends_with(name, ".las") || ends_with(name, ".laz") || ends_with(name, ".e57");
  if (!ply && !foreign) {
    throw std::invalid_argument(options.to.string() + ": unknown export format (expected .ply, .las, .laz, .copc.laz or .e57)");
  }
  if (foreign && !hooks.export_writer) {
    throw std::invalid_argument(options.to.string() + ": LAS/LAZ, COPC and E57 are written by minemap's Python package: " +
                                "run `python -m minemap export ...` (pip install . in minemap's source), or export .ply");
  }
  SurveyExport scans(options.out, settings);
  const auto start = std::chrono::steady_clock::now();
  ProgressBar bar(!options.quiet);
  const auto stop = [] { return signals::interrupted(); };
  ExportSummary summary;
  if (ply) {
    summary = write_export_ply(scans, options.to, stop, [&](std::size_t done, std::uint64_t) {
      bar(done, scans.scans(), "exporting");
    });
  } else {
    summary = hooks.export_writer(scans, options.to, stop);
  }
  if (!summary.completed) {
    say(stderr, "minemap: interrupted after %zu of %zu scans: %s was not written\n", summary.scans,
                 scans.scans(), options.to.c_str());
    return static_cast<int>(ExitCode::kInterrupted);
  }
  for (const std::string& warning : summary.warnings) say(stderr, "minemap: warning: %s\n", warning.c_str());
  if (!scans.skipped().empty()) {
    say(stderr, "minemap: warning: %zu unregistered scan(s) left out (%s%s); --scans names them to export them\n",
                 scans.skipped().size(), scans.skipped().front().c_str(), scans.skipped().size() > 1 ? ", ..." : "");
  }
  if (!options.quiet) {
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    say(stdout, "wrote %s: %llu points of %zu scans (%s; attributes: %s, scan index) in %.1f s\n", options.to.c_str(),
                static_cast<unsigned long long>(summary.points), summary.scans, scans.frame_description().c_str(),
                describe_attributes(summary.attributes).c_str(), seconds);
  }
  return 0;
}

}  // namespace minemap::cli
