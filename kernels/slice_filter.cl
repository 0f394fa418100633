// Slice filtering (paper, section IV.C): per 2D slice, a median filter over a window of range
// neighbours (by index in scanner order), applied only where the point's range differs from the
// median range by more than a threshold, then a reduction that joins consecutive close points into
// their mean so that consecutive output points are at least `min_spacing` apart.
// One work-item per kept slice; mirrors src/minemap/filter/slice_filter_cpu.cpp step for step.

inline float mm_squared_range(float4 p) { return mm_squared_norm3(p.x, p.y, p.z); }

// Index (into the slice) of the lower-median-range point of the window around `i`.
inline int mm_median_index(__global const float4* slice, int count, int i, int half_window) {
  float keys[MM_MAX_MEDIAN_WINDOW];
  int ids[MM_MAX_MEDIAN_WINDOW];
  const int first = max(0, i - half_window);
  const int last = min(count - 1, i + half_window);
  int n = 0;
  for (int j = first; j <= last; ++j) {
    // Insertion sort by (squared range, index): ties resolved by index, as on the CPU.
    mm_insert_sorted(keys, ids, n, mm_squared_range(slice[j]), j);
    ++n;
  }
  return ids[(n - 1) / 2];
}

// Emits a cluster mean, merging it into earlier outputs while they are closer than min_spacing.
inline void mm_emit(__global float4* out, int* out_count, float3 mean, float weight, float min_spacing_sq) {
  while (*out_count > 0) {
    const float4 last = out[*out_count - 1];
    if (!(mm_squared_distance(mean, last.xyz) < min_spacing_sq)) break;
    const float total = weight + last.w;
    mean = (float3)((mean.x * weight + last.x * last.w) / total, (mean.y * weight + last.y * last.w) / total,
                    (mean.z * weight + last.z * last.w) / total);
    weight = total;
    *out_count -= 1;
  }
  out[*out_count] = (float4)(mean, weight);
  *out_count += 1;
}

__kernel void filter_slices(__global const float4* points, __global const int* slice_offsets,
                            __global const int* kept_slices, const int kept_count, const int half_window,
                            const float outlier_threshold, const float min_spacing, const int apply_median,
                            const int apply_reduction, __global float4* out_points, __global int* out_counts,
                            __global int* outliers_replaced) {
  const int k = get_global_id(0);
  if (k >= kept_count) return;
  const int slice = kept_slices[k];
  const int begin = slice_offsets[slice];
  const int count = slice_offsets[slice + 1] - begin;
  __global const float4* in = points + begin;
  __global float4* out = out_points + begin;
  const float min_spacing_sq = min_spacing * min_spacing;

  int out_count = 0;
  int replaced = 0;
  float3 cluster_sum = (float3)(0.0f, 0.0f, 0.0f);
  float3 anchor = (float3)(0.0f, 0.0f, 0.0f);
  int cluster_size = 0;
  for (int i = 0; i < count; ++i) {
    float3 p = in[i].xyz;
    if (apply_median) {
      const int m = mm_median_index(in, count, i, half_window);
      const float range = sqrt(mm_squared_range(in[i]));
      const float median_range = sqrt(mm_squared_range(in[m]));
      if (fabs(range - median_range) > outlier_threshold) {
        p = in[m].xyz;
        ++replaced;
      }
    }
    if (!apply_reduction) {
      out[out_count++] = (float4)(p, 1.0f);
      continue;
    }
    if (cluster_size == 0) {
      cluster_sum = p;
      anchor = p;
      cluster_size = 1;
    } else if (mm_squared_distance(p, anchor) < min_spacing_sq) {
      cluster_sum += p;
      cluster_size += 1;
    } else {
      const float n = (float)cluster_size;
      mm_emit(out, &out_count, (float3)(cluster_sum.x / n, cluster_sum.y / n, cluster_sum.z / n), n, min_spacing_sq);
      cluster_sum = p;
      anchor = p;
      cluster_size = 1;
    }
  }
  if (apply_reduction && cluster_size > 0) {
    const float n = (float)cluster_size;
    mm_emit(out, &out_count, (float3)(cluster_sum.x / n, cluster_sum.y / n, cluster_sum.z / n), n, min_spacing_sq);
  }
  out_counts[k] = out_count;
  outliers_replaced[k] = replaced;
}
