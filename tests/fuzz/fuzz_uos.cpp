// Fuzzes the 3DTK .3d reader (read_uos_points) with two settings, and checks that whatever it accepts
// survives write_uos_points -> read_uos_points: same count, same slices, same file-frame points.
#include <cmath>

#include "fuzz_input.hpp"

namespace {

void check_round_trip(const minemap::Scan& scan) {
  using namespace minemap;
  const auto copy = fuzz::scratch_dir() / "round_trip.3d";
  io::write_uos_points(copy, scan);
  const Scan back = io::read_uos_points(copy, fuzz::fuzz_settings());  // must not throw
  fuzz::expect_or_abort(back.size() == scan.size(), "point count changed");
  fuzz::expect_or_abort(back.slice_offsets == scan.slice_offsets, "slices changed");
  // Points are floats around one local origin, so their resolution follows the cloud's overall
  // magnitude: a point at 20 cm in a cloud that also reaches 10^10 cm is only known to ~10^3 cm.
  double magnitude = 1.0;
  for (std::size_t i = 0; i < scan.size(); ++i) magnitude = std::max(magnitude, scan.file_point(i).cwiseAbs().maxCoeff());
  const double tolerance = 1e-6 * magnitude;
  for (std::size_t i = 0; i < scan.size(); ++i) {
    fuzz::expect_or_abort((scan.file_point(i) - back.file_point(i)).cwiseAbs().maxCoeff() <= tolerance, "point moved");
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace minemap;
  const auto path = fuzz::write_input(data, size, "scan000.3d");
  fuzz::read_expecting_input_errors(path, [](const auto& p) { check_round_trip(io::read_uos_points(p, fuzz::fuzz_settings())); });
  fuzz::read_expecting_input_errors(path, [](const auto& p) {
    io::ReadSettings settings = fuzz::fuzz_settings();
    settings.points_per_slice = 7;
    settings.unit = LengthUnit::kMetre;
    settings.right_handed_to_3dtk = true;
    io::read_uos_points(p, settings);
  });
  return 0;
}
