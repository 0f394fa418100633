// Fuzzes the PCD reader (ascii, binary, binary_compressed with LZF), and checks that an accepted
// cloud survives write_pcd(binary_compressed) -> read_pcd with the same number of points.
#include <cmath>

#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace minemap;
  const auto path = fuzz::write_input(data, size, "cloud.pcd");
  fuzz::read_expecting_input_errors(path, [](const auto& p) {
    const Scan scan = io::read_pcd(p, fuzz::fuzz_settings());
    // The writer stores float metres: coordinates beyond float range cannot round-trip (by design).
    for (std::size_t i = 0; i < scan.size(); ++i) {
      if (!(scan.file_point(i).cwiseAbs().maxCoeff() < 1e30)) return;
    }
    if (!(scan.pose_cm.col(3).cwiseAbs().maxCoeff() < 1e30)) return;
    const auto copy = fuzz::scratch_dir() / "round_trip.pcd";
    io::write_pcd(copy, scan, io::PcdEncoding::kBinaryCompressed);
    const Scan back = io::read_pcd(copy, fuzz::fuzz_settings());
    fuzz::expect_or_abort(back.size() == scan.size(), "point count changed in a PCD round trip");
  });
  return 0;
}
