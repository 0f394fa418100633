// Closest-point search on the flat bucket kd-tree (paper, section IV.D) and the ICP sums.
// Mirrors src/minemap/search/pairing_math.hpp: same traversal order, same strict '<' ties.
//
// Tree layout (uploaded unchanged from minemap::KdTree):
//   nodes  int8 {axis (-1 = leaf), a, b, split bits, left_max, right_min, 0, 0}; inner: a/b =
//          children, left_max/right_min = the children's extents along the axis (float bits);
//          leaf: a = first point, b = points to scan (1 for a bucket of copies), split bits = leaf index
//   points float4 {x, y, z, original index bits}
//   means  float4 {x, y, z, count} per leaf

// `method` of nearest_in_tree: exact search with backtracking, or the approximate kd-tree (brute
// force has its own kernel, nearest_brute_force).
#define MM_APPROXIMATE 1

inline float mm_squared_distance_to_box(float3 q, float4 lo, float4 hi) {
  const float3 below = fmax(lo.xyz - q, (float3)(0.0f));
  const float3 above = fmax(q - hi.xyz, (float3)(0.0f));
  const float3 d = below + above;
  return (d.x * d.x + d.y * d.y) + d.z * d.z;
}

// One query against one model: updates best (squared distance bound) and the hit, returns 1 when
// a closer model point was found. `hit_position` is in the MODEL frame. The exact search passes
// over points whose original index lies in [skip_first, skip_first + skip_count) (SkippedPoints).
inline int mm_search_model(float3 q, __global const int8* nodes, __global const float4* tree_points,
                           __global const float4* leaf_means, const int method, const int skip_first,
                           const int skip_count, float* best, int* hit_index, float3* hit_position) {
  int found = 0;
  if (method == MM_APPROXIMATE) {
    int node = 0;
    int8 n = nodes[0];
    while (n.s0 >= 0) {
      const float split = as_float(n.s3);
      node = ((n.s0 == 0 ? q.x : (n.s0 == 1 ? q.y : q.z)) < split) ? n.s1 : n.s2;
      n = nodes[node];
    }
    const float4 mean = leaf_means[n.s3];
    const float d = mm_squared_distance(q, mean.xyz);
    if (d < *best) {
      *best = d;
      *hit_index = -1;
      *hit_position = mean.xyz;
      found = 1;
    }
    return found;
  }
  // Exact search with incremental cell distances (see exact_nearest in pairing_math.hpp).
  int stack_node[MM_MAX_KD_DEPTH];
  float stack_bound[MM_MAX_KD_DEPTH];
  float3 stack_offset[MM_MAX_KD_DEPTH];
  int top = 0;
  int node = 0;
  float lower_bound = 0.0f;
  float3 offset = (float3)(0.0f);
  for (;;) {
    int8 n = nodes[node];
    while (n.s0 >= 0) {
      const int axis = n.s0;
      const float v = axis == 0 ? q.x : (axis == 1 ? q.y : q.z);
      const int go_left = v < as_float(n.s3);
      const float gap = go_left ? as_float(n.s5) - v : v - as_float(n.s4);
      const float axis_offset = axis == 0 ? offset.x : (axis == 1 ? offset.y : offset.z);
      const float far_bound = (lower_bound - axis_offset * axis_offset) + gap * gap;
      if (far_bound < *best) {
        stack_node[top] = go_left ? n.s2 : n.s1;
        stack_bound[top] = far_bound;
        float3 far_offset = offset;
        if (axis == 0) far_offset.x = gap;
        else if (axis == 1) far_offset.y = gap;
        else far_offset.z = gap;
        stack_offset[top] = far_offset;
        ++top;
      }
      node = go_left ? n.s1 : n.s2;
      n = nodes[node];
    }
    for (int i = n.s1, end = n.s1 + n.s2; i < end; ++i) {
      const float4 p = tree_points[i];
      const float d = mm_squared_distance(p.xyz, q);
      if (d < *best && (uint)(as_int(p.w) - skip_first) >= (uint)skip_count) {
        *best = d;
        *hit_index = as_int(p.w);
        *hit_position = p.xyz;
        found = 1;
      }
    }
    for (;;) {
      if (top == 0) return found;
      --top;
      if (stack_bound[top] < *best) break;
    }
    node = stack_node[top];
    lower_bound = stack_bound[top];
    offset = stack_offset[top];
  }
}

// The bound a query starts from: the closest pair found in earlier models of the union, or the
// maximum pair distance; the first model's launch also clears the query's result.
inline float mm_start_bound(const int i, const float max_squared_distance, const int first_model,
                            __global float4* best_pair, __global int2* best_ref) {
  if (first_model) {
    best_pair[i] = (float4)(0.0f, 0.0f, 0.0f, -1.0f);
    best_ref[i] = (int2)(-1, -1);
    return max_squared_distance;
  }
  const float previous = best_pair[i].w;
  return previous >= 0.0f ? previous : max_squared_distance;
}

// One work-item per data point. Keeps, across launches for several models (the union of a scan's
// neighbours), the closest pair so far: best_pair.xyz = model point in the DATA frame,
// best_pair.w = squared distance or -1; best_ref = (model id, original point index or -1).
__kernel void nearest_in_tree(__global const float4* data, const int data_count, __global const int8* nodes,
                              __global const float4* tree_points, __global const float4* leaf_means,
                              const float4 box_lo, const float4 box_hi, const float4 to_model0,
                              const float4 to_model1, const float4 to_model2, const float4 to_data0,
                              const float4 to_data1, const float4 to_data2, const int method,
                              const int skip_first, const int skip_count, const float max_squared_distance,
                              const int model_id, const int first_model, __global float4* best_pair,
                              __global int2* best_ref) {
  const int i = get_global_id(0);
  if (i >= data_count) return;
  float best = mm_start_bound(i, max_squared_distance, first_model, best_pair, best_ref);
  const float3 q = mm_apply_rigid(to_model0, to_model1, to_model2, data[i].xyz);
  if (!(mm_squared_distance_to_box(q, box_lo, box_hi) < best)) return;
  int hit_index = -1;
  float3 hit = (float3)(0.0f);
  if (mm_search_model(q, nodes, tree_points, leaf_means, method, skip_first, skip_count, &best, &hit_index, &hit)) {
    best_pair[i] = (float4)(mm_apply_rigid(to_data0, to_data1, to_data2, hit), best);
    best_ref[i] = (int2)(model_id, hit_index);
  }
}

// Brute force (Table I's baseline): every model point, tiled through local memory. The work-group
// size must equal MM_BRUTE_TILE. Visits points in tree order, as the CPU oracle does.
__kernel void nearest_brute_force(__global const float4* data, const int data_count,
                                  __global const float4* tree_points, const int tree_count, const float4 box_lo,
                                  const float4 box_hi, const float4 to_model0, const float4 to_model1,
                                  const float4 to_model2, const float4 to_data0, const float4 to_data1,
                                  const float4 to_data2, const float max_squared_distance, const int model_id,
                                  const int first_model, __global float4* best_pair, __global int2* best_ref) {
  __local float4 tile[MM_BRUTE_TILE];
  const int i = get_global_id(0);
  const int lid = get_local_id(0);
  const int active = i < data_count;
  float best = max_squared_distance;
  float3 q = (float3)(0.0f);
  if (active) {
    best = mm_start_bound(i, max_squared_distance, first_model, best_pair, best_ref);
    q = mm_apply_rigid(to_model0, to_model1, to_model2, data[i].xyz);
  }
  int hit_index = -1;
  float3 hit = (float3)(0.0f);
  for (int base = 0; base < tree_count; base += MM_BRUTE_TILE) {
    const int j = base + lid;
    tile[lid] = j < tree_count ? tree_points[j] : (float4)(0.0f);
    barrier(CLK_LOCAL_MEM_FENCE);
    const int limit = min(MM_BRUTE_TILE, tree_count - base);
    for (int t = 0; t < limit; ++t) {
      const float d = mm_squared_distance(tile[t].xyz, q);
      if (d < best) {
        best = d;
        hit_index = as_int(tile[t].w);
        hit = tile[t].xyz;
      }
    }
    barrier(CLK_LOCAL_MEM_FENCE);
  }
  if (active && hit_index >= 0) {
    best_pair[i] = (float4)(mm_apply_rigid(to_data0, to_data1, to_data2, hit), best);
    best_ref[i] = (int2)(model_id, hit_index);
  }
}

// The ICP sums over all pairs, centred on `reference` (data frame), each pair weighted by w (1, or
// the Geman-McClure kernel's weight when scale_squared > 0): count, sum w p', sum w m', sum w p' m'^T
// (row-major), sum |p - m|^2, sum w. Each work-item strides over the pairs; a tree reduction in
// local memory (work-group size a power of two) leaves one record of MM_SUM_TERMS floats per group.
// The host adds the group records in double in group order: no atomics, the same bits every run.
__kernel void pair_sums(__global const float4* data, __global const float4* best_pair, const int data_count,
                        const float4 reference, const float scale_squared, __global float* partials,
                        __local float* scratch) {
  const int lid = get_local_id(0);
  const int wg = get_local_size(0);
  float acc[MM_SUM_TERMS];
  for (int t = 0; t < MM_SUM_TERMS; ++t) acc[t] = 0.0f;
  for (int i = get_global_id(0); i < data_count; i += get_global_size(0)) {
    const float4 pair = best_pair[i];
    if (pair.w < 0.0f) continue;
    const float3 p = data[i].xyz - reference.xyz;
    const float3 m = pair.xyz - reference.xyz;
    const float pc[3] = {p.x, p.y, p.z};
    const float mc[3] = {m.x, m.y, m.z};
    // The Geman-McClure weight (mm_robust_weight's, in float): 1 when the scale is 0.
    float weight = 1.0f;
    if (scale_squared > 0.0f) {
      const float ratio = scale_squared / (scale_squared + pair.w);
      weight = ratio * ratio;
    }
    acc[MM_TERM_COUNT] += 1.0f;
    for (int r = 0; r < 3; ++r) {
      acc[MM_TERM_SUM_DATA + r] += weight * pc[r];
      acc[MM_TERM_SUM_MODEL + r] += weight * mc[r];
    }
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) acc[MM_TERM_SUM_DATA_MODEL + 3 * r + c] += weight * pc[r] * mc[c];
    }
    acc[MM_TERM_SUM_SQUARED_DISTANCE] += pair.w;
    acc[MM_TERM_WEIGHT] += weight;
  }
  for (int t = 0; t < MM_SUM_TERMS; ++t) scratch[t * wg + lid] = acc[t];
  barrier(CLK_LOCAL_MEM_FENCE);
  for (int stride = wg / 2; stride > 0; stride /= 2) {
    if (lid < stride) {
      for (int t = 0; t < MM_SUM_TERMS; ++t) scratch[t * wg + lid] += scratch[t * wg + lid + stride];
    }
    barrier(CLK_LOCAL_MEM_FENCE);
  }
  if (lid == 0) {
    for (int t = 0; t < MM_SUM_TERMS; ++t) partials[get_group_id(0) * MM_SUM_TERMS + t] = scratch[t * wg];
  }
}

#ifdef MM_HAVE_FP64
// The ICP sums exactly as the CPU backend makes them: work-item b sums the pairs of data points
// [b * MM_PAIR_SUM_BLOCK, (b + 1) * MM_PAIR_SUM_BLOCK) in double, in index order, through the
// C++ backend's own step (mm_add_point_to_point_terms, kernels/minemap_shared.h), and writes one
// record of MM_SUM_TERMS doubles; the host adds the records in block order as the CPU adds its
// blocks. The CPU and this kernel then produce the same bits, and so the same poses. Built only
// where the device has cl_khr_fp64 (the host passes -DMM_HAVE_FP64); elsewhere pair_sums (float).
__kernel void pair_sums_blocks(__global const float4* data, __global const float4* best_pair, const int data_count,
                               const double reference_x, const double reference_y, const double reference_z,
                               const float scale_squared, __global double* partials) {
  const int b = get_global_id(0);
  const int begin = b * MM_PAIR_SUM_BLOCK;
  if (begin >= data_count) return;
  const int end = min(data_count, begin + MM_PAIR_SUM_BLOCK);
  double acc[MM_SUM_TERMS];
  for (int t = 0; t < MM_SUM_TERMS; ++t) acc[t] = 0.0;
  for (int i = begin; i < end; ++i) {
    const float4 pair = best_pair[i];
    if (pair.w < 0.0f) continue;
    const float4 point = data[i];
    const double pc[3] = {(double)point.x - reference_x, (double)point.y - reference_y, (double)point.z - reference_z};
    const double mc[3] = {(double)pair.x - reference_x, (double)pair.y - reference_y, (double)pair.z - reference_z};
    mm_add_point_to_point_terms(acc, pc, mc, pair.w, mm_robust_weight(pair.w, scale_squared));
  }
  for (int t = 0; t < MM_SUM_TERMS; ++t) partials[b * MM_SUM_TERMS + t] = acc[t];
}
#endif
