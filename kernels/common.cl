// Shared by all minemap kernels (after kernels/minemap_shared.h, which the host prepends). OpenCL C
// 1.2, float only, except the ICP sums of pair_sums_blocks, built only where the device has
// cl_khr_fp64; no atomics on floats.

// A rigid transform as three rows (xyz = rotation row, w = translation), applied left to right in
// the same order as minemap::detail::RigidF::apply.
inline float3 mm_apply_rigid(float4 row0, float4 row1, float4 row2, float3 p) {
  return (float3)(((row0.x * p.x + row0.y * p.y) + row0.z * p.z) + row0.w,
                  ((row1.x * p.x + row1.y * p.y) + row1.z * p.z) + row1.w,
                  ((row2.x * p.x + row2.y * p.y) + row2.z * p.z) + row2.w);
}

inline float mm_squared_distance(float3 a, float3 b) { return mm_squared_distance3(a.x, a.y, a.z, b.x, b.y, b.z); }
