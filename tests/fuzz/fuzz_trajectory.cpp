// Fuzzes the other trajectory readers on the same bytes: 4x4 matrices, KITTI 3x4, gtsam graph, and
// the format detection of read_trajectory.
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace minemap;
  const auto path = fuzz::write_input(data, size, "trajectory.txt");
  fuzz::read_expecting_input_errors(path, [](const auto& p) { io::read_matrix_poses(p); });
  fuzz::read_expecting_input_errors(path, [](const auto& p) { io::read_kitti_poses(p); });
  fuzz::read_expecting_input_errors(path, [](const auto& p) { io::read_graph_poses(p); });
  fuzz::read_expecting_input_errors(path, [](const auto& p) { io::read_trajectory(p, LengthUnit::kCentimetre); });
  return 0;
}
