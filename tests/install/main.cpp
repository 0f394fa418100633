// The README's library example ("Using minemap as a library"), built against an installed minemap
// by tests/install/run_install_test.sh; a test checks that the README shows this file as it is.
#include <minemap/backend/cpu_backend.hpp>
#include <minemap/backend/make_backend.hpp>
#include <minemap/io/formats.hpp>
#include <minemap/slam/survey_matching.hpp>

#include <cstdio>

int main(int argc, char** argv) {
  using namespace minemap;
  // The backend is a value you own: the CPU (TBB), or make_backend({Backend::kAuto}) for an OpenCL
  // GPU where one works. Everything below runs on it.
  CpuBackend backend;

  // 1. Register two clouds (points in cm). Here: a room corner, and the same corner seen 3 cm away.
  std::vector<Eigen::Vector3f> model_points, data_points;
  for (float u = 0; u < 300; u += 5)
    for (float v = 0; v < 300; v += 5)
      for (const Eigen::Vector3f p : {Eigen::Vector3f(u, v, 0), Eigen::Vector3f(u, 0, v), Eigen::Vector3f(0, u, v)}) {
        model_points.push_back(p);
        data_points.push_back(p - Eigen::Vector3f(3, -2, 1));
      }
  auto model = backend.prepare(model_points, KdTreeSettings{});
  auto data = backend.prepare(data_points, KdTreeSettings{});
  const WorldModel models[] = {{model.get(), Pose::Identity()}};
  const IcpResult fit = register_icp(backend, *data, Pose::Identity(), models, IcpSettings::paper());
  const Eigen::Vector3d t = fit.world_from_data.block<3, 1>(0, 3);
  std::printf("pair: %s after %d iterations, t = (%.2f, %.2f, %.2f) cm\n", to_string(fit.stop), fit.iterations(),
              t.x(), t.y(), t.z());

  // 2. Map a survey folder (uos, PCD, PLY or KITTI) as `minemap map` does, with its defaults.
  if (argc < 2) return 0;
  const io::Survey survey = io::read_survey(argv[1]);
  const MappingResult map = map_survey(survey.scans, MappingSettings{}, backend);
  for (const ScanOutcome& scan : map.scans) {
    const Eigen::Vector3d p = scan.pose_cm.block<3, 1>(0, 3);
    std::printf("%s %s at (%.1f, %.1f, %.1f) cm\n", scan.name.c_str(), scan.registered ? "registered" : "FAILED",
                p.x(), p.y(), p.z());
  }
  const bool pair_ok = fit.converged() && (t - Eigen::Vector3d(3, -2, 1)).norm() < 0.01;
  return pair_ok && map.all_registered() ? 0 : 1;
}
