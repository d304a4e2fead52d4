// sRGB transfer (IEC 61966-2-1): colormap entries are sRGB-encoded RGBA8; shading happens in linear light and
// the sRGB colour attachment encodes again on store.
vec3 srgb_to_linear(vec3 c) {
  vec3 lo = c / 12.92;
  vec3 hi = pow((c + 0.055) / 1.055, vec3(2.4));
  return mix(hi, lo, lessThanEqual(c, vec3(0.04045)));
}
