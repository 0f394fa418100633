// A metascan's union (slam/local_map.cpp, ComputeBackend::placed_within): each scan's model points
// moved into the union's frame in double by the host's own step (mm_place_point,
// kernels/minemap_shared.h), cast to float, and marked kept when inside the reach box. One launch
// per scan, each writing its points from `out_offset` of one buffer; the host reads it once and keeps
// the marked points in order: the host's union bit for bit. Built only where the device has
// cl_khr_fp64 (MM_HAVE_FP64); elsewhere the host places them.

#ifdef MM_HAVE_FP64
__kernel void place_within(__global const float4* points, const int count, const double4 row0, const double4 row1,
                           const double4 row2, const double4 box_min, const double4 box_max, const int out_offset,
                           __global float4* out) {
  const int i = get_global_id(0);
  if (i >= count) return;
  const float4 p = points[i];
  const double rows[12] = {row0.x, row0.y, row0.z, row0.w, row1.x, row1.y, row1.z, row1.w,
                           row2.x, row2.y, row2.z, row2.w};
  double q[3];
  mm_place_point(rows, (double)p.x, (double)p.y, (double)p.z, q);
  // As the host: left out when below the box's minimum or above its maximum on any axis.
  const bool out_of_box = q[0] < box_min.x || q[1] < box_min.y || q[2] < box_min.z || q[0] > box_max.x ||
                          q[1] > box_max.y || q[2] > box_max.z;
  out[out_offset + i] = (float4)((float)q[0], (float)q[1], (float)q[2], out_of_box ? 0.0f : 1.0f);
}
#endif
