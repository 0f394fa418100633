// Fuzzes the KITTI .bin reader in both layouts (x y z intensity, x y z).
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace minemap;
  const auto path = fuzz::write_input(data, size, "000000.bin");
  fuzz::read_expecting_input_errors(path, [](const auto& p) { io::read_kitti_bin(p, fuzz::fuzz_settings(), 4); });
  fuzz::read_expecting_input_errors(path, [](const auto& p) { io::read_kitti_bin(p, fuzz::fuzz_settings(), 3); });
  return 0;
}
