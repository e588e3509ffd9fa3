// The compute path's large blobs (splat_comp.glsl lists them): a workgroup a
// blob, its threads taking the blob's pixels in turn, so that a blob of
// thousands of pixels costs what as many small ones do rather than one
// thread's long loop, and no sprite passes through a GPU's few graphics units.

layout(local_size_x = 256) in;

void main() {
  uint count = min(large_count, uint(large_blobs.length()));
  for (uint b = gl_WorkGroupID.x; b < count; b += gl_NumWorkGroups.x) {
    LargeBlob blob = large_blobs[b];
    ivec2 low, high;
    PixelBox(blob.center_major.xy, blob.center_major.z, low, high);
    if (any(lessThan(high, low))) continue;
    uint width = uint(high.x - low.x + 1), pixels = width * uint(high.y - low.y + 1);
    for (uint k = gl_LocalInvocationIndex; k < pixels; k += gl_WorkGroupSize.x) {
      ivec2 pixel = low + ivec2(int(k % width), int(k / width));
      AddPixel(pixel, blob.center_major.xy, blob.conic.xyz, blob.value);
    }
  }
}
