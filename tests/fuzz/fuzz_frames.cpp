// Fuzzes the 3DTK .frames reader, and checks that accepted frames survive write -> read unchanged.
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace minemap;
  const auto path = fuzz::write_input(data, size, "scan000.frames");
  fuzz::read_expecting_input_errors(path, [](const auto& p) {
    const auto frames = io::read_uos_frames(p, LengthUnit::kMetre);
    const auto copy = fuzz::scratch_dir() / "round_trip.frames";
    io::write_uos_frames(copy, frames, LengthUnit::kMetre);
    const auto back = io::read_uos_frames(copy, LengthUnit::kMetre);
    fuzz::expect_or_abort(back.size() == frames.size(), "frame count changed");
    for (std::size_t k = 0; k < frames.size(); ++k) {
      fuzz::expect_or_abort(back[k].type == frames[k].type, "frame type changed");
      const Pose difference = back[k].pose_cm - frames[k].pose_cm;
      const double scale = std::max(1.0, frames[k].pose_cm.cwiseAbs().maxCoeff());
      fuzz::expect_or_abort(difference.cwiseAbs().maxCoeff() <= 1e-9 * scale, "frame pose changed");
    }
  });
  return 0;
}
