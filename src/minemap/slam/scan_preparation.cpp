#include "minemap/slam/scan_preparation.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>

namespace minemap::detail {

ScanPreparation::VoxelMeans ScanPreparation::voxel_means(const Scan& scan) const {
  VoxelMeans means;
  if (settings_.reduction != Reduction::kVoxel) return means;
  if (scan.attributes.intensity.empty()) {
    means.data = backend_.voxel_means(scan.points_cm, settings_.voxel_cm);
  } else {
    means.data = backend_.voxel_means(scan.points_cm, settings_.voxel_cm, scan.attributes.intensity, &means.intensity);
  }
  if (settings_.voxel_models()) means.model = backend_.voxel_means(scan.points_cm, settings_.model_voxel_cm);
  return means;
}

/// The denser model cloud of a scan that is not reduced to voxel means (MappingSettings::
/// dense_models); `dense` false (and no points) when it would equal the data.
std::vector<Eigen::Vector3f> ScanPreparation::filtered_model(const Scan& scan, bool& dense) const {
  const bool filtered = scan.has_slices() && settings_.filter_enabled;
  dense = false;
  if (!settings_.dense_models) return {};
  if (filtered && settings_.model_slice_stride < settings_.filter.slice_stride) {
    SliceFilterSettings model_filter = settings_.filter;
    model_filter.slice_stride = settings_.model_slice_stride;
    dense = true;
    return backend_.filter_slices(scan, model_filter).points_cm;
  }
  if (!filtered && settings_.unstructured_point_stride > 1) {
    dense = true;
    return thin_unstructured(scan, 1);
  }
  return {};
}

ScanPreparation::Reduced ScanPreparation::reduce(const Scan& scan, VoxelMeans voxel, RunControl& control) {
  Reduced reduced;
  control.timed(&StageTimes::filter_s, [&] {
    std::vector<Eigen::Vector3f> points;
    if (settings_.reduction == Reduction::kVoxel) {
      points = std::move(voxel.data);
      reduced.intensity = std::move(voxel.intensity);
      reduced.has_model = !voxel.model.empty();
      reduced.model = std::move(voxel.model);
    } else {
      if (scan.has_slices() && settings_.filter_enabled) {
        SliceFilterResult filtered = backend_.filter_slices(scan, settings_.filter);
        reduced.outliers_replaced = filtered.outliers_replaced;
        points = std::move(filtered.points_cm);
      } else {
        if (!scan.has_slices() && settings_.filter_enabled) skipped_slice_filter_ = true;
        points = thin_unstructured(scan, settings_.unstructured_point_stride);
      }
      reduced.model = filtered_model(scan, reduced.has_model);
    }
    reduced.data = std::move(points);
  });
  const std::size_t stride = static_cast<std::size_t>(settings_.health.probe_stride);
  if (settings_.health.enabled && stride > 1) {
    for (std::size_t k = 0; k < reduced.data.size(); k += stride) reduced.probe.push_back(reduced.data[k]);
    reduced.has_probe = true;
  }
  return reduced;
}

void ScanPreparation::keep_for_the_map(PreparedScan& prepared, const Scan& scan, Reduced& reduced) const {
  // The points themselves are the data cloud's (share_with_the_map, once it is made).
  prepared.points_in = scan.size();
  prepared.outliers_replaced = reduced.outliers_replaced;
  if (!reduced.intensity.empty()) {
    prepared.used_intensity = std::make_shared<const std::vector<float>>(std::move(reduced.intensity));
  }
}

void share_with_the_map(PreparedScan& prepared) {
  // Not a copy: a tenth of a megabyte a scan on the simulated survey.
  prepared.used_points_cm = std::shared_ptr<const std::vector<Eigen::Vector3f>>(prepared.cloud, &prepared.cloud->point_vector());
}

TreeBuild ScanPreparation::model_trees_when() const {
  // The metascan (incremental matching, the default) takes the scans' points into a tree of its
  // own: their own trees are built only for a search that needs them (a loop's match). Pairwise
  // matching and the relaxation search every model's tree: built at once, in parallel.
  return settings_.mode == MatchingMode::kIncremental ? TreeBuild::kOnFirstUse : TreeBuild::kNow;
}

SweepTiming ScanPreparation::timing_of(const Scan& scan) const {
  if (settings_.motion.deskew == DeskewMode::kOff) return {};
  return sweep_timing(scan, settings_.motion.max_sweep_s);
}

PreparedScan ScanPreparation::prepare(const Scan& scan, RunControl& control, const SweepTiming& timing,
                                      const std::optional<Pose>& sweep_motion) {
  // A deskewed sweep is reduced from a copy whose points moved (its intensities go along).
  Scan deskewed;
  const bool deskewing = !timing.empty() && sweep_motion.has_value();
  if (deskewing) {
    control.timed(&StageTimes::filter_s, [&] {
      deskewed.name = scan.name;
      deskewed.local_origin_cm = scan.local_origin_cm;
      deskewed.slice_offsets = scan.slice_offsets;
      deskewed.attributes.intensity = scan.attributes.intensity;
      deskewed.points_cm = deskewed_points(scan, timing, *sweep_motion);
    });
  }
  const Scan& source = deskewing ? deskewed : scan;
  VoxelMeans voxel = control.timed(&StageTimes::filter_s, [&] { return voxel_means(source); });
  Reduced reduced = reduce(source, std::move(voxel), control);
  PreparedScan prepared;
  keep_for_the_map(prepared, source, reduced);
  if (!timing.empty()) {
    prepared.stamp_s = timing.stamp_s;
    prepared.sweep_s = timing.duration_s;
  }
  if (deskewing) prepared.sweep_motion = sweep_motion;
  const TreeBuild model_trees = model_trees_when();
  control.timed(&StageTimes::tree_build_s, [&] {
    prepared.cloud = backend_.prepare(std::move(reduced.data), settings_.tree,
                                      reduced.has_model ? TreeBuild::kOnFirstUse : model_trees);
    prepared.model_cloud =
        reduced.has_model ? backend_.prepare(std::move(reduced.model), settings_.tree, model_trees) : prepared.cloud;
    prepared.probe = reduced.has_probe ? backend_.prepare(std::move(reduced.probe), settings_.tree, TreeBuild::kOnFirstUse)
                                       : prepared.cloud;
    if (settings_.needs_planes()) prepared.planes.emplace(prepared.model_cloud->points(), settings_.plane_cell_cm);
  });
  share_with_the_map(prepared);
  return prepared;
}

std::vector<PreparedScan> ScanPreparation::prepare_all(std::span<const Scan> scans, RunControl& control) {
  const std::size_t n = scans.size();
  // Voxel means, the same bits on every backend: on the host one scan per task, on a device in turn.
  std::vector<VoxelMeans> voxel(n);
  control.timed(&StageTimes::filter_s, [&] {
    if (settings_.reduction != Reduction::kVoxel) return;
    if (backend_.concurrent_voxel_means()) {
      tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) { voxel[i] = voxel_means(scans[i]); });
    } else {
      for (std::size_t i = 0; i < n; ++i) voxel[i] = voxel_means(scans[i]);
    }
  });
  std::vector<PreparedScan> prepared(n);
  std::vector<std::vector<Eigen::Vector3f>> data(n), models, probes;
  std::vector<bool> has_model(n, false), has_probe(n, false);
  for (std::size_t i = 0; i < n; ++i) {  // in order: the slice filter runs on the backend
    Reduced reduced = reduce(scans[i], std::move(voxel[i]), control);
    keep_for_the_map(prepared[i], scans[i], reduced);
    data[i] = std::move(reduced.data);
    has_model[i] = reduced.has_model;
    has_probe[i] = reduced.has_probe;
    if (reduced.has_model) models.push_back(std::move(reduced.model));
    if (reduced.has_probe) probes.push_back(std::move(reduced.probe));
  }
  // Every tree at once (the CPU backend builds them in parallel); clouds in scan order.
  control.timed(&StageTimes::tree_build_s, [&] {
    // A data cloud that is also its scan's model is built as models are.
    const TreeBuild model_trees = model_trees_when();
    const bool any_alone = std::any_of(has_model.begin(), has_model.end(), [](bool b) { return !b; });
    auto data_clouds = backend_.prepare_many(std::move(data), settings_.tree,
                                             any_alone ? model_trees : TreeBuild::kOnFirstUse);
    auto model_clouds = backend_.prepare_many(std::move(models), settings_.tree, model_trees);
    auto probe_clouds = backend_.prepare_many(std::move(probes), settings_.tree, TreeBuild::kOnFirstUse);
    std::size_t next_model = 0, next_probe = 0;
    for (std::size_t i = 0; i < n; ++i) {
      PreparedScan& scan = prepared[i];
      scan.cloud = std::move(data_clouds[i]);
      scan.model_cloud = has_model[i] ? std::move(model_clouds[next_model++]) : scan.cloud;
      scan.probe = has_probe[i] ? std::move(probe_clouds[next_probe++]) : scan.cloud;
      share_with_the_map(scan);
    }
    if (settings_.needs_planes()) {
      tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
        prepared[i].planes.emplace(prepared[i].model_cloud->points(), settings_.plane_cell_cm);
      });
    }
  });
  return prepared;
}

}  // namespace minemap::detail
