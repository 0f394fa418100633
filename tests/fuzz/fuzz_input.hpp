#pragma once
// Shared by the fuzz targets (tests/fuzz/fuzz_*.cpp). The readers take paths, so the fuzzer's bytes
// are written to a per-process temp file first. An InputError is the expected answer to malformed
// input; every other exception escapes LLVMFuzzerTestOneInput and libFuzzer reports it as a crash,
// as it does for sanitizer findings and for failed round-trip checks (expect_or_abort).
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "minemap/core/error.hpp"
#include "minemap/io/formats.hpp"

namespace minemap::fuzz {

/// A folder for this process's inputs, removed at exit.
inline const std::filesystem::path& scratch_dir() {
  struct Scratch {
    std::filesystem::path dir;
    Scratch() {
      dir = std::filesystem::temp_directory_path() / ("minemap-fuzz-" + std::to_string(::getpid()));
      std::filesystem::create_directories(dir);
    }
    ~Scratch() {
      std::error_code ignored;
      std::filesystem::remove_all(dir, ignored);
    }
  };
  static const Scratch scratch;
  return scratch.dir;
}

/// Writes `size` bytes to scratch_dir()/name and returns the path.
inline std::filesystem::path write_input(const std::uint8_t* data, std::size_t size, const std::string& name) {
  const auto path = scratch_dir() / name;
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return path;
}

/// Settings for fuzzing: a small max_points keeps every accepted input cheap.
inline io::ReadSettings fuzz_settings() {
  io::ReadSettings settings;
  settings.max_points = 1 << 20;
  return settings;
}

/// Calls `read(path)`; an InputError ends the run normally, anything else propagates.
template <class Read>
void read_expecting_input_errors(const std::filesystem::path& path, Read&& read) {
  try {
    read(path);
  } catch (const InputError&) {
  }
}

/// A broken invariant (e.g. a round trip that changed the data): crash so libFuzzer keeps the input.
inline void expect_or_abort(bool condition, const char* what) {
  if (!condition) {
    std::fprintf(stderr, "fuzz invariant failed: %s\n", what);
    std::abort();
  }
}

}  // namespace minemap::fuzz
