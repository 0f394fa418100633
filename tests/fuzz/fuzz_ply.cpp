// Fuzzes the PLY reader (ascii and binary_little_endian, lists, other elements).
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace minemap;
  const auto path = fuzz::write_input(data, size, "cloud.ply");
  fuzz::read_expecting_input_errors(path, [](const auto& p) { io::read_ply(p, fuzz::fuzz_settings()); });
  return 0;
}
