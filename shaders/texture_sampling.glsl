// Sampling a texture of the cache image by its wrap modes (TextureGpu.colour.w, from sampling.bin), with the
// filtering done here: the sampler's own addressing would wrap at the edges of the whole layer, not of the
// texture's region inside it. Bilinear from four texelFetch per level, trilinear between two levels, each texel
// index wrapped (repeat, mirrored repeat) or clamped inside the region, so a seam filters across to the other
// edge exactly as a sampler with that address mode would. Needs `cache_images` declared by the includer.

// The texture's cache image (its texel format's plane) and layer, from TextureGpu.placement.x.
uint texture_plane(TextureGpu tex) { return tex.placement.x >> kPlacementPlaneShift; }
int texture_layer(TextureGpu tex) { return int(tex.placement.x & kPlacementLayerMask); }

// A sample of plane `plane`. The array is indexed by constants only: an index that differs between the
// fragments of one draw would need descriptor indexing (not core Vulkan 1.2; lavapipe has it, not every GPU).
vec4 cache_lod(uint plane, vec3 st, float lod) {
  if (plane == 1u) return textureLod(cache_images[1], st, lod);
  if (plane == 2u) return textureLod(cache_images[2], st, lod);
  if (plane == 3u) return textureLod(cache_images[3], st, lod);
  return textureLod(cache_images[0], st, lod);
}

vec4 cache_fetch(uint plane, ivec3 texel, int level) {
  if (plane == 1u) return texelFetch(cache_images[1], texel, level);
  if (plane == 2u) return texelFetch(cache_images[2], texel, level);
  if (plane == 3u) return texelFetch(cache_images[3], texel, level);
  return texelFetch(cache_images[0], texel, level);
}

// Texel index `i` of a level `n` texels wide, addressed as the mode says (Vulkan's REPEAT, MIRRORED_REPEAT,
// CLAMP_TO_EDGE).
int wrap_index(int i, int n, uint mode) {
  if (mode == kWrapRepeat) return ((i % n) + n) % n;
  if (mode == kWrapMirror) {
    int m = ((i % (2 * n)) + 2 * n) % (2 * n);
    return m < n ? m : 2 * n - 1 - m;
  }
  return clamp(i, 0, n - 1);
}

// Bilinear at integer level `level` (resident), texture coordinate `uv` (any value: the modes wrap it).
vec4 fetch_level_wrapped(TextureGpu tex, vec2 uv, int level) {
  ivec2 e = max(ivec2(tex.region.zw) >> level, ivec2(1));
  ivec2 base = ivec2(tex.region.xy) >> level;
  uint wu = (tex.colour.w >> kSamplingWrapUShift) & kSamplingWrapMask;
  uint wv = (tex.colour.w >> kSamplingWrapVShift) & kSamplingWrapMask;
  vec2 p = uv * vec2(e) - 0.5;
  vec2 fl = floor(p);
  vec2 f = p - fl;
  ivec2 i0 = ivec2(fl);
  int x0 = wrap_index(i0.x, e.x, wu), x1 = wrap_index(i0.x + 1, e.x, wu);
  int y0 = wrap_index(i0.y, e.y, wv), y1 = wrap_index(i0.y + 1, e.y, wv);
  int layer = texture_layer(tex);
  uint plane = texture_plane(tex);
  vec4 t00 = cache_fetch(plane, ivec3(base + ivec2(x0, y0), layer), level);
  vec4 t10 = cache_fetch(plane, ivec3(base + ivec2(x1, y0), layer), level);
  vec4 t01 = cache_fetch(plane, ivec3(base + ivec2(x0, y1), layer), level);
  vec4 t11 = cache_fetch(plane, ivec3(base + ivec2(x1, y1), layer), level);
  return mix(mix(t00, t10, f.x), mix(t01, t11, f.x), f.y);
}

// Trilinear at `lod`, which lies between the texture's finest and coarsest resident levels.
vec4 sample_wrapped(TextureGpu tex, vec2 uv, float lod) {
  int l0 = int(floor(lod));
  float f = lod - float(l0);
  vec4 c = fetch_level_wrapped(tex, uv, l0);
  if (f > 0.0) c = mix(c, fetch_level_wrapped(tex, uv, l0 + 1), f);
  return c;
}

bool texture_wraps(TextureGpu tex) {
  return (((tex.colour.w >> kSamplingWrapUShift) | (tex.colour.w >> kSamplingWrapVShift)) & kSamplingWrapMask) != 0u;
}

bool texture_alpha_tested(TextureGpu tex) { return (tex.colour.w & kSamplingAlphaTest) != 0u; }

float texture_alpha_cutoff(TextureGpu tex) { return float((tex.colour.w >> kSamplingCutoffShift) & 0xffu) / 255.0; }
