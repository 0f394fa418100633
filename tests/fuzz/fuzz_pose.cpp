// Fuzzes the 3DTK .pose reader, and checks that an accepted pose survives write_uos_pose ->
// read_uos_pose as the same matrix (the writer's exact Euler decomposition, gimbal lock included).
#include <cmath>

#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace minemap;
  const auto path = fuzz::write_input(data, size, "scan000.pose");
  fuzz::read_expecting_input_errors(path, [](const auto& p) {
    const Pose pose = euler_to_pose(io::read_uos_pose(p));
    if (!pose.allFinite()) return;  // sin/cos of finite angles are finite; kept as a guard
    const auto copy = fuzz::scratch_dir() / "round_trip.pose";
    io::write_uos_pose(copy, pose);
    const Pose back = euler_to_pose(io::read_uos_pose(copy));
    const double rotation_error = (back.topLeftCorner(3, 3) - pose.topLeftCorner(3, 3)).cwiseAbs().maxCoeff();
    fuzz::expect_or_abort(rotation_error < 1e-9, "rotation changed in a .pose round trip");
    fuzz::expect_or_abort(back.col(3) == pose.col(3), "position changed in a .pose round trip");
  });
  fuzz::read_expecting_input_errors(path, [](const auto& p) { io::read_uos_pose(p, LengthUnit::kMetre); });
  return 0;
}
