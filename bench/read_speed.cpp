// Reading at the disk's speed (issue 28, item 3): how fast `minemap map` parses a survey against how
// fast the same files can merely be read. One run, side by side, for each cache state asked:
//   cat     `cat FILES > /dev/null` (one process, the scan files in name order): the disk, or the
//           page cache when warm;
//   read    the same files read() by T threads at once, no parsing: what T threads can fetch;
//   parse   io::read_survey_in_parts, T threads, a part of 4 scans a thread, each part's points
//           let go as it comes (as `minemap map` reads: PartwiseMapper); the whole survey's checks
//           (truth, duplicates, units) included.
// MB/s is the scan files' bytes over the wall time. --cold drops the page cache before each
// measurement (root: sync, then 3 > /proc/sys/vm/drop_caches); without it the survey is read once
// first so all three find it cached (when it fits in memory).
//
//   build/bench/read_speed SURVEY [--threads 2] [--cold] [--repeats 3] [--json FILE]
#include <fcntl.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "minemap/io/formats.hpp"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

/// The survey's scan files (what the reader parses), in name order.
std::vector<fs::path> scan_files(const fs::path& dir) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string extension = entry.path().extension().string();
    if (entry.is_regular_file() && (extension == ".3d" || extension == ".pcd" || extension == ".ply" ||
                                    extension == ".bin" || extension == ".xyz")) {
      files.push_back(entry.path());
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

bool drop_caches() {
  ::sync();
  std::ofstream drop("/proc/sys/vm/drop_caches");
  drop << "3\n";
  drop.flush();
  return static_cast<bool>(drop);
}

double time_cat(const std::vector<fs::path>& files) {
  // Through xargs: the list may be longer than one command line allows.
  const std::string list = (fs::temp_directory_path() / "minemap-read-speed.list").string();
  {
    std::ofstream out(list, std::ios::binary);
    for (const fs::path& file : files) out << file.string() << '\0';
  }
  const auto start = Clock::now();
  const int status = std::system(("xargs -0 cat < '" + list + "' > /dev/null").c_str());
  const double wall = seconds_since(start);
  fs::remove(list);
  if (status != 0) {
    std::fprintf(stderr, "read_speed: cat failed\n");
    std::exit(1);
  }
  return wall;
}

double time_read(const std::vector<fs::path>& files) {
  const auto start = Clock::now();
  tbb::parallel_for(std::size_t{0}, files.size(), [&](std::size_t k) {
    const int fd = ::open(files[k].c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return;
    std::vector<char> buffer(1 << 20);
    while (::read(fd, buffer.data(), buffer.size()) > 0) {
    }
    ::close(fd);
  });
  return seconds_since(start);
}

double time_parse(const fs::path& dir, std::size_t part_scans, std::size_t& points) {
  points = 0;
  const auto start = Clock::now();
  minemap::io::read_survey_in_parts(dir, {}, part_scans, [&](std::vector<minemap::Scan>& part, std::size_t, std::size_t) {
    for (minemap::Scan& scan : part) {  // let the points go, as the mapper does once a part is matched
      points += scan.size();
      std::vector<Eigen::Vector3f>().swap(scan.points_cm);
      std::vector<std::uint32_t>().swap(scan.slice_offsets);
      scan.attributes = {};
    }
    return true;
  });
  return seconds_since(start);
}

}  // namespace

int main(int argc, char** argv) {
  fs::path survey;
  int threads = 2, repeats = 3;
  bool cold = false;
  std::string json_path;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--threads" && i + 1 < argc) {
      threads = std::atoi(argv[++i]);
    } else if (arg == "--repeats" && i + 1 < argc) {
      repeats = std::atoi(argv[++i]);
    } else if (arg == "--cold") {
      cold = true;
    } else if (arg == "--json" && i + 1 < argc) {
      json_path = argv[++i];
    } else if (survey.empty() && arg.rfind("--", 0) != 0) {
      survey = arg;
    } else {
      std::fprintf(stderr, "usage: read_speed SURVEY [--threads T] [--cold] [--repeats N] [--json FILE]\n");
      return 2;
    }
  }
  if (survey.empty() || threads < 1 || repeats < 1) {
    std::fprintf(stderr, "usage: read_speed SURVEY [--threads T] [--cold] [--repeats N] [--json FILE]\n");
    return 2;
  }
  const std::vector<fs::path> files = scan_files(survey);
  if (files.empty()) {
    std::fprintf(stderr, "read_speed: no scan files in %s\n", survey.c_str());
    return 2;
  }
  double bytes = 0.0;
  for (const fs::path& file : files) bytes += static_cast<double>(fs::file_size(file));
  const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
  const std::size_t part_scans = 4 * static_cast<std::size_t>(threads);
  if (cold && !drop_caches()) {
    std::fprintf(stderr, "read_speed: --cold needs root (cannot write /proc/sys/vm/drop_caches)\n");
    return 2;
  }
  if (!cold) time_read(files);  // warm the cache

  std::printf("%zu files, %.1f MB, %d threads, page cache %s\n", files.size(), bytes / 1e6, threads,
              cold ? "dropped before each" : "warm");
  std::vector<double> cat_s, read_s, parse_s;
  std::size_t points = 0;
  for (int r = 0; r < repeats; ++r) {
    if (cold) drop_caches();
    cat_s.push_back(time_cat(files));
    if (cold) drop_caches();
    read_s.push_back(time_read(files));
    if (cold) drop_caches();
    parse_s.push_back(time_parse(survey, part_scans, points));
    std::printf("  repeat %d: cat %.2f s, read %.2f s, parse %.2f s\n", r + 1, cat_s.back(), read_s.back(),
                parse_s.back());
    std::fflush(stdout);
  }
  const auto best = [](const std::vector<double>& v) { return *std::min_element(v.begin(), v.end()); };
  const double cat = best(cat_s), read = best(read_s), parse = best(parse_s);
  std::printf("fastest of %d: cat %.0f MB/s, read (%d threads) %.0f MB/s, parse %.0f MB/s (%.2f x cat, %.1f M points/s)\n",
              repeats, bytes / 1e6 / cat, threads, bytes / 1e6 / read, bytes / 1e6 / parse, cat / parse,
              static_cast<double>(points) / 1e6 / parse);
  if (!json_path.empty()) {
    std::ofstream json(json_path);
    json << "{\n  \"survey\": \"" << survey.string() << "\",\n  \"files\": " << files.size()
         << ",\n  \"bytes\": " << static_cast<long long>(bytes) << ",\n  \"points\": " << points
         << ",\n  \"threads\": " << threads << ",\n  \"cold\": " << (cold ? "true" : "false")
         << ",\n  \"seconds_fastest\": {\"cat\": " << cat << ", \"read\": " << read << ", \"parse\": " << parse
         << "},\n  \"mb_per_s\": {\"cat\": " << bytes / 1e6 / cat << ", \"read\": " << bytes / 1e6 / read
         << ", \"parse\": " << bytes / 1e6 / parse << "}\n}\n";
  }
  return 0;
}
