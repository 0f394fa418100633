// Voxel means (filter/voxel_filter.hpp) on the device, the same bits as the host's voxel_mean_filter:
// cells numbered in the order their first point appears, each mean summed in double in point order.
// Five steps, each a launch; none depends on the order in which work-items run:
//   voxel_insert   each point's cell (floor in double, as the host), found or added in a hash table
//                  (64-bit compare-and-swap); the cell's first point by atomic_min, its count by
//                  atomic_inc: both the same whatever the order
//   voxel_scan     per work-group, the exclusive prefix sums over points of (is first, count if
//                  first): the cell's number and where its points start; the host adds the groups'
//                  totals in order (a few thousand integers) and hands them back
//   voxel_cells    each first point writes its cell's number, start and count
//   voxel_members  each point takes a place in its cell's list (atomic_inc: in any order)...
//   voxel_sum      ...which each cell sorts by point index before summing: the host's order.
// Built only where the device has cl_khr_fp64 and cl_khr_int64_base_atomics (MM_HAVE_VOXEL_MEANS);
// elsewhere the host computes them. A cell coordinate outside +-2^20 (a point beyond 10 km at 1 cm
// cells) or a point that is not finite sets *status and the host computes the cloud instead.

#ifdef MM_HAVE_VOXEL_MEANS
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable

#define MM_VOXEL_EMPTY_KEY 0xFFFFFFFFFFFFFFFFUL
#define MM_VOXEL_NO_POINT 0xFFFFFFFFu
#define MM_VOXEL_CELL_BITS 21
#define MM_VOXEL_HALF_RANGE (1L << (MM_VOXEL_CELL_BITS - 1))

inline long mm_voxel_cell(float v, double inverse) { return (long)floor((double)v * inverse); }

__kernel void voxel_insert(__global const float4* points, const uint count, const double inverse,
                           __global ulong* keys, __global uint* first, __global uint* counts, const uint mask,
                           __global uint* slot_of, __global int* status) {
  const uint i = get_global_id(0);
  if (i >= count) return;
  const float4 p = points[i];
  if (!isfinite(p.x) || !isfinite(p.y) || !isfinite(p.z)) {
    atomic_or(status, 1);
    slot_of[i] = 0;
    return;
  }
  const long c[3] = {mm_voxel_cell(p.x, inverse), mm_voxel_cell(p.y, inverse), mm_voxel_cell(p.z, inverse)};
  ulong key = 0;
  for (int a = 0; a < 3; ++a) {
    if (c[a] < -MM_VOXEL_HALF_RANGE || c[a] >= MM_VOXEL_HALF_RANGE) {
      atomic_or(status, 1);
      slot_of[i] = 0;
      return;
    }
    key |= (ulong)(c[a] + MM_VOXEL_HALF_RANGE) << (MM_VOXEL_CELL_BITS * a);
  }
  uint slot = (uint)((key * 0x9E3779B97F4A7C15UL) >> 32) & mask;
  while (true) {
    const ulong was = atom_cmpxchg((volatile __global ulong*)&keys[slot], MM_VOXEL_EMPTY_KEY, key);
    if (was == MM_VOXEL_EMPTY_KEY || was == key) break;
    slot = (slot + 1) & mask;
  }
  slot_of[i] = slot;
  atomic_min(&first[slot], i);
  atomic_inc(&counts[slot]);
}

// Exclusive prefix sums within each work-group (a power of two) of x = (point i is its cell's
// first) and y = (its cell's count when first, else 0); the group's totals into group_totals.
__kernel void voxel_scan(__global const uint* slot_of, __global const uint* first, __global const uint* counts,
                         const uint count, __global uint2* prefix, __global uint2* group_totals,
                         __local uint2* scratch) {
  const uint i = get_global_id(0);
  const uint l = get_local_id(0);
  const uint n = get_local_size(0);
  uint2 mine = (uint2)(0u, 0u);
  if (i < count && first[slot_of[i]] == i) mine = (uint2)(1u, counts[slot_of[i]]);
  scratch[l] = mine;
  barrier(CLK_LOCAL_MEM_FENCE);
  // Hillis-Steele, inclusive: integers, so any order gives the same sums.
  for (uint step = 1; step < n; step <<= 1) {
    const uint2 add = l >= step ? scratch[l - step] : (uint2)(0u, 0u);
    barrier(CLK_LOCAL_MEM_FENCE);
    scratch[l] += add;
    barrier(CLK_LOCAL_MEM_FENCE);
  }
  if (i < count) prefix[i] = scratch[l] - mine;
  if (l == n - 1) group_totals[get_group_id(0)] = scratch[l];
}

// Each cell's first point: the cell's number (in order of first appearance), where its members
// start and how many; the slot learns its cell.
__kernel void voxel_cells(__global const uint* slot_of, __global const uint* first, __global const uint* counts,
                          const uint count, __global const uint2* prefix, __global const uint2* group_offsets,
                          __global uint* cell_of_slot, __global uint* cell_start, __global uint* cell_count) {
  const uint i = get_global_id(0);
  if (i >= count) return;
  const uint slot = slot_of[i];
  if (first[slot] != i) return;
  const uint2 at = prefix[i] + group_offsets[get_group_id(0)];
  cell_of_slot[slot] = at.x;
  cell_start[at.x] = at.y;
  cell_count[at.x] = counts[slot];
}

__kernel void voxel_members(__global const uint* slot_of, const uint count, __global const uint* cell_of_slot,
                            __global const uint* cell_start, __global uint* filled, __global uint* member_list) {
  const uint i = get_global_id(0);
  if (i >= count) return;
  const uint cell = cell_of_slot[slot_of[i]];
  member_list[cell_start[cell] + atomic_inc(&filled[cell])] = i;
}

// One work-item per cell: its members sorted by point index (insertion sort: a cell holds a few
// points, a dense one some hundreds), then summed in double in that order and divided, as the host.
__kernel void voxel_sum(__global const float4* points, __global const float* values, const int with_values,
                        const uint cells, __global const uint* cell_start, __global const uint* cell_count,
                        __global uint* member_list, __global float4* means) {
  const uint c = get_global_id(0);
  if (c >= cells) return;
  __global uint* list = member_list + cell_start[c];
  const uint n = cell_count[c];
  for (uint k = 1; k < n; ++k) {
    const uint v = list[k];
    uint j = k;
    for (; j > 0 && list[j - 1] > v; --j) list[j] = list[j - 1];
    list[j] = v;
  }
  double x = 0.0, y = 0.0, z = 0.0, w = 0.0;
  for (uint k = 0; k < n; ++k) {
    const float4 p = points[list[k]];
    x += (double)p.x;
    y += (double)p.y;
    z += (double)p.z;
    if (with_values) w += (double)values[list[k]];
  }
  const double d = (double)n;
  means[c] = (float4)((float)(x / d), (float)(y / d), (float)(z / d), (float)(w / d));
}
#endif
