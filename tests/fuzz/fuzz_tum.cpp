// Fuzzes the TUM trajectory reader.
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace minemap;
  const auto path = fuzz::write_input(data, size, "trajectory.tum");
  fuzz::read_expecting_input_errors(path, [](const auto& p) { io::read_tum(p); });
  return 0;
}
