/* Streaming copy used by the benchmark to measure the device's attainable memory bandwidth (the
 * yardstick for "fraction of bandwidth" of the element kernels). 16-byte words. */
__kernel void bandwidth_copy(const uint count, __global const float4* restrict src,
                             __global float4* restrict dst) {
  const uint i = get_global_id(0);
  if (i < count) dst[i] = src[i];
}
