// Consumer of an installed minemap: builds against the exported minemap::minemap target.
#include <minemap/search/kdtree.hpp>
#include <minemap/core/pose.hpp>
#include <cstdio>
int main() {
  std::vector<Eigen::Vector3f> pts = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  minemap::KdTree tree(pts);
  std::printf("nodes %zu, pose ok %d\n", tree.nodes().size(), minemap::is_valid_rigid(minemap::Pose::Identity()));
}
