// Pose errors of a registered survey against its reference poses, computed as `minemap map` does
// (pose_errors: relative to the first scan): the yardstick bench/slam6d_compare.sh applies to
// minemap and to 3DTK's slam6D alike.
//   usage: pose_error SURVEY [FRAMES_DIR]
// SURVEY is a uos survey with truth/ (what `minemap simulate` writes); the estimated pose of scan
// NNN is the last line of FRAMES_DIR/scanNNN.frames (default: SURVEY itself, where slam6D writes
// them; `minemap map --out OUT` writes them to OUT). Prints one JSON object.
#include <cstdio>
#include <exception>
#include <filesystem>
#include <string>
#include <vector>

#include "minemap/io/formats.hpp"
#include "minemap/slam/survey_matching.hpp"

int main(int argc, char** argv) {
  using namespace minemap;
  if (argc < 2 || argc > 3) {
    std::fprintf(stderr, "usage: %s SURVEY [FRAMES_DIR]\n", argv[0]);
    return 2;
  }
  try {
    const std::filesystem::path survey_dir = argv[1];
    const std::filesystem::path frames_dir = argc == 3 ? std::filesystem::path(argv[2]) : survey_dir;
    const io::Survey survey = io::read_survey(survey_dir);
    if (!survey.truth_cm) throw std::runtime_error(survey_dir.string() + " has no reference poses (truth/)");
    std::vector<Pose> estimated;
    for (const Scan& scan : survey.scans) {
      const auto frames = io::read_uos_frames(frames_dir / (scan.name + ".frames"), survey.unit);
      if (frames.empty()) throw std::runtime_error(scan.name + ".frames is empty");
      estimated.push_back(frames.back().pose_cm);
    }
    const PoseErrors e = pose_errors(estimated, *survey.truth_cm);
    std::printf("{\"scans\": %zu, \"mean_translation_cm\": %.4f, \"max_translation_cm\": %.4f, "
                "\"percent_of_path\": %.5f, \"mean_rotation_deg\": %.5f, \"path_cm\": %.2f, "
                "\"mean_step_translation_cm\": %.4f, \"mean_step_rotation_deg\": %.5f}\n",
                estimated.size(), e.mean_translation_cm, e.max_translation_cm,
                e.path_length_cm > 0 ? 100.0 * e.mean_translation_cm / e.path_length_cm : 0.0, e.mean_rotation_deg,
                e.path_length_cm, e.mean_relative_translation_cm, e.mean_relative_rotation_deg);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "pose_error: %s\n", e.what());
    return 1;
  }
}
