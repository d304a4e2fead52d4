#pragma once
// texstream-bench pages' view of a huge texture on the ground: a pinhole camera over the plane z = 0 that the
// texture covers, its needbuffer (seed 004 §3.2.3: which page at which level each pixel wants) and its frames,
// drawn on the CPU through the page table exactly as the page shader samples (the page to use: the wanted one
// or its nearest resident ancestor; bilinear taps inside its bordered page; trilinear between two levels), or
// from the whole pyramid (an ordinary mipmapped texture: the reference). docs/design/pages.md.
#include <cstdint>
#include <functional>
#include <vector>

#include "texstream/common/page_file.hpp"
#include "texstream/stream/page_policy.hpp"

namespace texstream::bench {

struct GroundPose {
  double x = 0, y = 0, z = 0;  // metres; the texture covers [0, width * metres_per_texel] x [0, height * …]
  double yaw = 0;              // radians, counter-clockwise from +x, about +z
  double pitch = 0;            // radians, negative looks down
};

struct GroundView {
  uint32_t width = 0, height = 0;  // pixels
  double fov_x = 1.0472;           // horizontal field of view, radians (60°)
  double metres_per_texel = 0.25;  // at the finest level
};

// Per pixel: where the ray meets the texture (virtual-square units, 0..1) and the fractional level it wants.
struct GroundSample {
  bool hit = false;
  double u = 0, v = 0;
  double level = 0;  // page-file level, fractional; finest = levels - 1
  double distance = 0;
};

// Samples of a frame (row-major); pixels whose ray misses the texture have hit = false.
std::vector<GroundSample> cast_ground(const GroundView& view, const GroundPose& pose, const pages::PageGeometry& g,
                                      uint32_t step = 1);

// The needbuffer of every `step`-th pixel in x and y: for each hit the pages at the floor and the ceiling of its
// level (trilinear filtering reads both).
std::vector<pages::PageNeedSample> needbuffer(const GroundView& view, const GroundPose& pose,
                                              const pages::PageGeometry& g, uint32_t step);

// Texel (x, y) of `level`, any coordinates (the reference clamps them).
using TexelFetch = std::function<uint32_t(uint32_t level, int64_t x, int64_t y)>;
// A stored page's texels, stored_side()^2 RGBA8.
using PageTexels = std::function<const uint32_t*(pages::PageId)>;

constexpr uint32_t kGroundBackground = 0xff806040u;  // pixels that see no texture, the same in every frame

// A frame through the page table: trilinear between the pixel's two levels, each bilinear in the page the table
// gives for it. `shown_level` (optional, per pixel) receives the finer level actually sampled.
void draw_pages(const std::vector<GroundSample>& samples, const pages::PageGeometry& g, const pages::PageTable& table,
                const PageTexels& texels, std::vector<uint32_t>& rgba, std::vector<float>* shown_level = nullptr);
// The same frame from an ordinary mipmapped texture.
void draw_reference(const std::vector<GroundSample>& samples, const pages::PageGeometry& g, const TexelFetch& fetch,
                    std::vector<uint32_t>& rgba);

}  // namespace texstream::bench
