#include "atlas_builder.hpp"

#include <squish.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "bc1_encoder.hpp"
#include "mip_chain.hpp"
#include "texstream/common/dds.hpp"
#include "texstream/common/mesh_index.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/common/staged_folder.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::atlas {

namespace fs = std::filesystem;

namespace {

// A texture's place in an atlas (texels at level 0; x, y multiples of w, h).
struct Placement {
  uint32_t atlas = 0;  // index into the atlases
  uint32_t x = 0, y = 0, w = 0, h = 0;
};

struct Atlas {
  TexelFormat format = TexelFormat::kBc1;
  uint32_t width = 0, height = 0;  // powers of two
  std::vector<uint32_t> textures;  // old ids, in placement order
};

// The global axis closest to a direction: 0..5 = +x, -x, +y, -y, +z, -z.
uint32_t closest_axis(const std::array<double, 3>& n) {
  uint32_t best = 4;  // a degenerate normal counts as up
  double best_v = 0;
  for (uint32_t a = 0; a < 3; ++a) {
    if (std::abs(n[a]) > best_v) best_v = std::abs(n[a]), best = 2 * a + (n[a] < 0 ? 1 : 0);
  }
  return best;
}

// Power-of-two rectangles into a power-of-two rectangle, each at a multiple of its own size, so that its level
// L is the atlas's texels at level L: a binary buddy system of free power-of-two rectangles. A request takes the
// smallest free rectangle that holds it (lowest Morton code of its corner on ties, so the used part stays
// compact and the atlas can be cut to the power-of-two rectangle around it) and halves it, along the side with
// more to spare, until it is exactly the request; each half not taken goes back.
class BuddyPacker {
 public:
  BuddyPacker(uint32_t width, uint32_t height) { give(width, height, 0, 0); }

  std::optional<std::pair<uint32_t, uint32_t>> allocate(uint32_t w, uint32_t h) {
    const auto lw = static_cast<uint32_t>(std::countr_zero(w)), lh = static_cast<uint32_t>(std::countr_zero(h));
    // The smallest free shape that holds w x h; among equal areas the squarest.
    std::optional<std::tuple<uint32_t, uint32_t, uint32_t>> best;  // area log, |aspect|, shape key
    for (const auto& [shape, list] : free_) {
      if (list.empty()) continue;
      const uint32_t fw = shape >> 8, fh = shape & 0xffu;
      if (fw < lw || fh < lh) continue;
      const auto cand = std::tuple(fw + fh, fw > fh ? fw - fh : fh - fw, shape);
      if (!best || cand < *best) best = cand;
    }
    if (!best) return std::nullopt;
    const uint32_t shape = std::get<2>(*best);
    auto& list = free_[shape];
    auto [x, y] = list.begin()->second;
    list.erase(list.begin());
    uint32_t fw = 1u << (shape >> 8), fh = 1u << (shape & 0xffu);
    while (fw > w || fh > h) {
      if (fw / w >= fh / h) {  // more to spare across: keep the left half
        fw /= 2;
        give(fw, fh, x + fw, y);
      } else {
        fh /= 2;
        give(fw, fh, x, y + fh);
      }
    }
    return std::pair(x, y);
  }

 private:
  static uint64_t morton(uint32_t x, uint32_t y) {
    uint64_t m = 0;
    for (uint32_t b = 0; b < 32; ++b)
      m |= (uint64_t{(x >> b) & 1u} << (2 * b)) | (uint64_t{(y >> b) & 1u} << (2 * b + 1));
    return m;
  }
  void give(uint32_t w, uint32_t h, uint32_t x, uint32_t y) {
    const uint32_t shape = static_cast<uint32_t>(std::countr_zero(w)) << 8 | static_cast<uint32_t>(std::countr_zero(h));
    free_[shape].emplace(morton(x, y), std::pair(x, y));
  }

  std::map<uint32_t, std::map<uint64_t, std::pair<uint32_t, uint32_t>>> free_;  // by (log2 w << 8 | log2 h)
};

std::array<double, 3> rotate(const scene::MeshTransform& t, const float v[3]) {
  const double qx = t.rotation[0], qy = t.rotation[1], qz = t.rotation[2], qw = t.rotation[3];
  const double vx = v[0], vy = v[1], vz = v[2];
  // v + 2w (q x v) + 2 q x (q x v)
  const double cx = qy * vz - qz * vy, cy = qz * vx - qx * vz, cz = qx * vy - qy * vx;
  const double ccx = qy * cz - qz * cy, ccy = qz * cx - qx * cz, ccz = qx * cy - qy * cx;
  return {vx + 2 * (qw * cx + ccx), vy + 2 * (qw * cy + ccy), vz + 2 * (qw * cz + ccz)};
}

Result<std::vector<uint8_t>> read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) return make_error(ErrorCode::kNotFound, p.string() + ": cannot open");
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return bytes;
}

Status write_file(const fs::path& p, const std::vector<uint8_t>& bytes) {
  std::error_code ec;
  fs::create_directories(p.parent_path(), ec);
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (!out) return make_error(ErrorCode::kIo, p.string() + ": cannot write");
  return ok_status();
}

// A texture file's levels, in the layout texstream-gen and texstream-import write (or any DDS of that format).
struct TextureFile {
  std::vector<uint8_t> bytes;
  scene::DdsLayout layout;
  std::span<const uint8_t> level(uint32_t l) const {
    return std::span(bytes).subspan(layout.mip_offset(l), layout.mip_size(l));
  }
};

Result<TextureFile> read_texture(const fs::path& dir, uint32_t id, const scene::TextureRecord& r) {
  const fs::path p = scene::texture_path(dir, TextureId(id));
  auto bytes = read_file(p);
  if (!bytes) return bytes.error();
  TextureFile f{std::move(*bytes), {}};
  auto layout = scene::parse_dds_layout(std::as_bytes(std::span(f.bytes)), p.string());
  if (!layout) return layout.error();
  f.layout = *layout;
  if (f.layout.encoding == scene::DdsEncoding::kOther ||
      f.layout.texel_format() != static_cast<TexelFormat>(r.format) || f.layout.width != r.width ||
      f.layout.height != r.height || f.layout.mip_count < r.mip_count ||
      f.layout.mip_offset(r.mip_count - 1) + f.layout.mip_size(r.mip_count - 1) > f.bytes.size()) {
    return make_error(ErrorCode::kCorrupt, p.string() + ": does not hold the " + std::to_string(r.width) + "x" +
                                               std::to_string(r.height) + " " +
                                               std::string(to_string(static_cast<TexelFormat>(r.format))) +
                                               " chain textures.bin lists");
  }
  return f;
}

uint32_t block_of(TexelFormat f) { return is_block_compressed(f) ? 4 : 1; }

// Decodes one level (w x h texels) of `format` into RGBA8 texels (R in the low byte).
void decode_level(TexelFormat format, std::span<const uint8_t> bytes, uint32_t w, uint32_t h,
                  std::vector<uint32_t>& out) {
  out.resize(size_t{w} * h);
  if (format == TexelFormat::kRgba8) {
    std::memcpy(out.data(), bytes.data(), out.size() * 4);
    return;
  }
  const int flags = format == TexelFormat::kBc1 ? squish::kDxt1 : squish::kDxt5;
  const uint32_t bw = (w + 3) / 4, bh = (h + 3) / 4, bb = format == TexelFormat::kBc1 ? 8 : 16;
  for (uint32_t by = 0; by < bh; ++by)
    for (uint32_t bx = 0; bx < bw; ++bx) {
      squish::u8 rgba[64];
      squish::Decompress(rgba, bytes.data() + (size_t{by} * bw + bx) * bb, flags);
      for (uint32_t y = 0; y < 4 && 4 * by + y < h; ++y)
        for (uint32_t x = 0; x < 4 && 4 * bx + x < w; ++x)
          std::memcpy(&out[size_t{4 * by + y} * w + 4 * bx + x], rgba + 4 * (4 * y + x), 4);
    }
}

void encode(TexelFormat format, const uint32_t* rgba, uint32_t w, uint32_t h, std::span<uint8_t> out) {
  if (format == TexelFormat::kBc1) {
    gen::encode_bc1(rgba, w, h, out);
  } else if (format == TexelFormat::kBc3) {
    gen::encode_bc3(rgba, w, h, out);
  } else {
    std::memcpy(out.data(), rgba, size_t{w} * h * 4);
  }
}

// The atlas's whole chain as a DDS file, and its 1x1 colour. Level by level: the blocks a packed texture covers
// whole at that level are its own bytes; the rest (empty space, and levels where textures are smaller than a
// block) are the level above filtered in linear light and encoded.
Result<std::pair<std::vector<uint8_t>, uint32_t>> build_atlas_file(const fs::path& in_dir, const Atlas& a,
                                                                   std::span<const scene::TextureRecord> records,
                                                                   std::span<const Placement> placement) {
  const TexelFormat f = a.format;
  const uint32_t levels = full_mip_count(a.width, a.height), block = block_of(f);
  std::vector<TextureFile> files;
  for (uint32_t t : a.textures) {
    auto file = read_texture(in_dir, t, records[t]);
    if (!file) return file.error();
    files.push_back(std::move(*file));
  }
  std::vector<uint8_t> out(scene::dds_file_bytes(f, a.width, a.height, levels));
  const auto header = scene::make_dds_header(f, a.width, a.height, levels);
  std::memcpy(out.data(), header.data(), header.size());
  std::vector<uint32_t> prev, cur, patch(size_t{block} * block);
  const uint32_t bb = f == TexelFormat::kRgba8 ? 4 : static_cast<uint32_t>(block_bytes(f));
  uint32_t pw = 0, ph = 0;
  for (uint32_t l = 0; l < levels; ++l) {
    const Extent2D e = mip_extent(a.width, a.height, l);
    const std::span<uint8_t> dst(out.data() + scene::dds_mip_offset(f, a.width, a.height, l),
                                 mip_bytes(f, e.width, e.height, 0));
    // Filtered from the level above (level 0: a mid grey where no texture lies, never sampled there).
    cur.assign(size_t{e.width} * e.height, 0xff808080u);
    if (l > 0) gen::downsample_linear(prev.data(), pw, ph, cur.data(), e.width, e.height);
    if (e.width >= block && e.height >= block) {
      const uint32_t bw = e.width / block, bh = e.height / block;
      std::vector<bool> copied(size_t{bw} * bh, false);
      for (size_t k = 0; k < a.textures.size(); ++k) {
        const Placement& p = placement[a.textures[k]];
        const uint32_t w = p.w >> l, h = p.h >> l;
        if (w < block || h < block) continue;  // smaller than a block here: filtered below
        const std::span<const uint8_t> src = files[k].level(l);
        const uint32_t x0 = (p.x >> l) / block, y0 = (p.y >> l) / block, sw = w / block;
        for (uint32_t by = 0; by < h / block; ++by) {
          std::memcpy(dst.data() + (size_t{y0 + by} * bw + x0) * bb, src.data() + size_t{by} * sw * bb,
                      size_t{sw} * bb);
          for (uint32_t bx = 0; bx < sw; ++bx) copied[size_t{y0 + by} * bw + x0 + bx] = true;
        }
      }
      for (uint32_t by = 0; by < bh; ++by)
        for (uint32_t bx = 0; bx < bw; ++bx) {
          if (copied[size_t{by} * bw + bx]) continue;
          for (uint32_t y = 0; y < block; ++y)
            for (uint32_t x = 0; x < block; ++x)
              patch[size_t{y} * block + x] = cur[size_t{by * block + y} * e.width + bx * block + x];
          encode(f, patch.data(), block, block, dst.subspan((size_t{by} * bw + bx) * bb, bb));
        }
    } else {
      encode(f, cur.data(), e.width, e.height, dst);  // a side below one block: the whole level is filtered
    }
    // What the level really holds (the copies, and the encoding's loss) is what the next level filters.
    decode_level(f, dst, e.width, e.height, cur);
    prev.swap(cur);
    pw = e.width, ph = e.height;
  }
  return std::pair(std::move(out), prev[0]);
}

}  // namespace

Result<AtlasStats> build_atlases(const AtlasOptions& opt, const AtlasProgress& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  if (opt.atlas_px < 4 || !std::has_single_bit(opt.atlas_px) || opt.atlas_px > 16384)
    return make_error(ErrorCode::kInvalidArgument,
                      "atlas side " + std::to_string(opt.atlas_px) + " is not a power of two in 4..16384");
  if (!(opt.cell_m > 0) || !std::isfinite(opt.cell_m))
    return make_error(ErrorCode::kInvalidArgument, "cell size must be a positive number of metres");
  const fs::path in = fs::absolute(opt.in).lexically_normal();
  const fs::path out = fs::absolute(opt.out).lexically_normal();
  if (in == out)
    return make_error(ErrorCode::kInvalidArgument, "--out must differ from the input scene " + in.string());
  std::error_code ec;
  // Written beside --out and renamed into place: a failed run leaves nothing half written.
  auto staged = StagedFolder::create(out, opt.force, "atlas");
  if (!staged) return staged.error();
  const fs::path tmp = staged->dir();

  auto manifest = scene::read_manifest(in);
  if (!manifest) return manifest.error();
  auto md = scene::read_meshes(in);
  if (!md) return md.error();
  auto records = scene::read_texture_table(in);
  if (!records) return records.error();
  const uint64_t n = records->size();
  auto colours = scene::read_colormap(in, n);
  if (!colours) return colours.error();
  std::vector<uint32_t> sampling(n, 0);
  bool has_sampling = false;
  if (auto s = scene::map_sampling(in, n)) {
    sampling.assign(s->flags.begin(), s->flags.end());
    has_sampling = true;
  } else if (s.error().code != ErrorCode::kNotFound) {
    return s.error();
  }
  std::vector<scene::MeshTransform> transforms;
  if (auto t = scene::map_transforms(in, md->meshes.size())) {
    transforms.assign(t->transforms.begin(), t->transforms.end());
  } else if (t.error().code != ErrorCode::kNotFound) {
    return t.error();
  }

  AtlasStats st;
  st.textures_in = n;
  st.meshes = md->meshes.size();

  // ---- which textures may be packed, and the group of each (its first mesh's cell and orientation) ----
  std::vector<bool> eligible(n, false);
  for (uint64_t t = 0; t < n; ++t) {
    const scene::TextureRecord& r = (*records)[t];
    const auto f = static_cast<TexelFormat>(r.format);
    eligible[t] = (f == TexelFormat::kBc1 || f == TexelFormat::kBc3 || f == TexelFormat::kRgba8) &&
                  std::has_single_bit(r.width) && std::has_single_bit(r.height) && r.width >= 4 && r.height >= 4 &&
                  r.width <= opt.atlas_px && r.height <= opt.atlas_px &&
                  r.mip_count == full_mip_count(r.width, r.height) && sampling[t] == 0;
  }
  struct Group {
    int64_t cx = 0, cy = 0;
    uint32_t axis = 0;
    bool set = false;
  };
  std::vector<Group> group(n);
  constexpr float kUvSlack = 1e-4f;  // a texel of a 16 K texture is 6e-5
  for (size_t i = 0; i < md->meshes.size(); ++i) {
    const scene::MeshRecord& m = md->meshes[i];
    if (m.texture_id >= n)
      return make_error(ErrorCode::kCorrupt, "meshes.bin: mesh " + std::to_string(i) + " names texture " +
                                                 std::to_string(m.texture_id) + " of " + std::to_string(n));
    std::array<double, 3> normal{};
    for (uint32_t v = 0; v < m.vertex_count; ++v) {
      const scene::Vertex& vx = md->vertices[size_t{m.first_vertex} + v];
      if (vx.uv[0] < -kUvSlack || vx.uv[0] > 1 + kUvSlack || vx.uv[1] < -kUvSlack || vx.uv[1] > 1 + kUvSlack)
        eligible[m.texture_id] = false;
      const auto r = transforms.empty() ? std::array<double, 3>{vx.normal[0], vx.normal[1], vx.normal[2]}
                                        : rotate(transforms[i], vx.normal);
      for (int a = 0; a < 3; ++a) normal[a] += r[a];
    }
    Group& g = group[m.texture_id];
    if (g.set) continue;
    g.set = true;
    const double cx = m.origin[0] + 0.5 * (static_cast<double>(m.bounds_min[0]) + static_cast<double>(m.bounds_max[0]));
    const double cy = m.origin[1] + 0.5 * (static_cast<double>(m.bounds_min[1]) + static_cast<double>(m.bounds_max[1]));
    g.cx = static_cast<int64_t>(std::floor(cx / opt.cell_m));
    g.cy = static_cast<int64_t>(std::floor(cy / opt.cell_m));
    g.axis = closest_axis(normal);
  }

  // ---- packing: per (format, cell), groups in axis order, rows of one height ----
  std::vector<uint32_t> order;
  for (uint32_t t = 0; t < n; ++t) {
    if (eligible[t] && group[t].set) {
      order.push_back(t);
    } else {
      ++st.kept_not_eligible;
    }
  }
  std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
    const scene::TextureRecord &ra = (*records)[a], &rb = (*records)[b];
    // Within a cell: orientation group, then largest first (the buddy packer fills best in decreasing sizes).
    const auto key = [&](uint32_t t, const scene::TextureRecord& r) {
      return std::tuple(r.format, group[t].cx, group[t].cy, group[t].axis, -int64_t{std::max(r.width, r.height)},
                        -int64_t{std::min(r.width, r.height)}, t);
    };
    return key(a, ra) < key(b, rb);
  });
  std::vector<Placement> placement(n);
  std::vector<bool> packed(n, false);
  std::vector<Atlas> atlases;
  {
    const uint32_t A = opt.atlas_px;
    size_t i = 0;
    while (i < order.size()) {
      // One cell of one format.
      const uint32_t f = (*records)[order[i]].format;
      const int64_t cx = group[order[i]].cx, cy = group[order[i]].cy;
      size_t end = i;
      while (end < order.size() && (*records)[order[end]].format == f && group[order[end]].cx == cx &&
             group[order[end]].cy == cy)
        ++end;
      // Atlases of the cell one after the other. Each starts as the smallest square the cell's remaining texels
      // could fill and doubles while they do not all fit, up to the atlas side; a full atlas still takes every
      // later texture that fits its holes (the seed fills an atlas's empty space from the next orientation
      // group), and what did not fit goes on to the next atlas.
      std::vector<uint32_t> remaining(order.begin() + static_cast<std::ptrdiff_t>(i),
                                      order.begin() + static_cast<std::ptrdiff_t>(end));
      i = end;
      while (!remaining.empty()) {
        uint64_t area = 0;
        for (uint32_t t : remaining) {
          const scene::TextureRecord& r = (*records)[t];
          area += uint64_t{r.width} * r.height;
        }
        // Candidate shapes: powers of two up to the atlas side, at least the remaining area, at most 4:1, by
        // area then squareness; the first that holds every remaining texture, else the whole atlas side.
        std::vector<std::pair<uint32_t, uint32_t>> shapes;
        for (uint32_t w = 4; w <= A; w *= 2)
          for (uint32_t h = 4; h <= A; h *= 2)
            if (uint64_t{w} * h >= area && w <= 4 * h && h <= 4 * w) shapes.emplace_back(w, h);
        std::sort(shapes.begin(), shapes.end(), [](const auto& p, const auto& q) {
          const uint64_t ap = uint64_t{p.first} * p.second, aq = uint64_t{q.first} * q.second;
          if (ap != aq) return ap < aq;
          return (p.first > p.second ? p.first / p.second : p.second / p.first) <
                 (q.first > q.second ? q.first / q.second : q.second / q.first);
        });
        shapes.emplace_back(A, A);
        Atlas cur{static_cast<TexelFormat>(f), 0, 0, {}};
        std::vector<uint32_t> left;
        for (const auto& [sw, sh] : shapes) {
          BuddyPacker packer(sw, sh);
          cur.textures.clear();
          left.clear();
          for (uint32_t t : remaining) {
            const scene::TextureRecord& r = (*records)[t];
            const auto at = r.width <= sw && r.height <= sh ? packer.allocate(r.width, r.height) : std::nullopt;
            if (!at) {
              left.push_back(t);
              continue;
            }
            placement[t] = Placement{0, at->first, at->second, r.width, r.height};
            cur.textures.push_back(t);
          }
          if (left.empty() || (sw == A && sh == A)) break;
        }
        remaining.swap(left);
        if (cur.textures.size() < 2) continue;  // one texture is its own atlas already: kept as it is
        // The smallest power-of-two rectangle that holds what was placed.
        uint32_t right = 4, bottom = 4;
        for (uint32_t t : cur.textures) {
          right = std::max(right, placement[t].x + placement[t].w);
          bottom = std::max(bottom, placement[t].y + placement[t].h);
        }
        cur.width = std::bit_ceil(right);
        cur.height = std::bit_ceil(bottom);
        for (uint32_t t : cur.textures) placement[t].atlas = static_cast<uint32_t>(atlases.size()), packed[t] = true;
        atlases.push_back(cur);
      }
    }
  }

  // ---- new texture ids: in the order of the old ids, an atlas where its first texture was ----
  // What each new id is: an old texture kept as it was, or an atlas.
  struct Source {
    bool atlas = false;
    uint32_t index = 0;  // old texture id, or index into `atlases`
  };
  std::vector<uint32_t> new_id(n);
  std::vector<int64_t> atlas_id(atlases.size(), -1);
  std::vector<Source> source;  // by new id
  uint32_t next = 0;
  for (uint32_t t = 0; t < n; ++t) {
    if (!packed[t]) {
      new_id[t] = next++;
      source.push_back({false, t});
      continue;
    }
    const uint32_t a = placement[t].atlas;
    if (atlas_id[a] < 0) {
      atlas_id[a] = next++;
      source.push_back({true, a});
    }
    new_id[t] = static_cast<uint32_t>(atlas_id[a]);
  }
  st.atlases = atlases.size();
  st.textures_out = next;
  for (uint32_t t = 0; t < n; ++t) {
    if (packed[t]) {
      ++st.textures_packed;
      st.texel_bytes_in +=
          mip_bytes(static_cast<TexelFormat>((*records)[t].format), (*records)[t].width, (*records)[t].height, 0);
    } else {
      ++st.textures_kept;
    }
  }
  for (const Atlas& a : atlases) {
    st.atlas_bytes += mip_bytes(a.format, a.width, a.height, 0);
  }

  // ---- meshes: UVs into the atlas; shared geometry copied where its users end in different places ----
  scene::MeshData out_md;
  out_md.vertices = md->vertices;
  out_md.indices = md->indices;
  out_md.meshes = md->meshes;
  std::map<std::pair<uint32_t, uint32_t>, std::pair<uint32_t, scene::MeshRecord>> range_owner;  // -> (new tex, rec)
  for (auto& m : out_md.meshes) {
    const uint32_t old = m.texture_id;
    const uint32_t tex = new_id[old];
    const auto key = std::pair(m.first_vertex, m.first_index);
    auto [it, first] = range_owner.try_emplace(key, tex, m);
    // Shared as it was when neither user's UVs change, or both change the same way (one atlas, one rectangle).
    const uint32_t first_old = it->second.second.texture_id;
    const bool same_place =
        !first && ((!packed[old] && !packed[first_old]) ||
                   (packed[old] && packed[first_old] && it->second.first == tex &&
                    placement[old].x == placement[first_old].x && placement[old].y == placement[first_old].y &&
                    placement[old].w == placement[first_old].w && placement[old].h == placement[first_old].h));
    m.texture_id = tex;
    if (!first && same_place) {
      m.first_vertex = it->second.second.first_vertex;
      m.first_index = it->second.second.first_index;
      continue;
    }
    if (!first) {
      // Another user of this geometry shows another texture (or another place): its own copy.
      const auto fv = static_cast<uint32_t>(out_md.vertices.size()), fi = static_cast<uint32_t>(out_md.indices.size());
      out_md.vertices.insert(out_md.vertices.end(), md->vertices.begin() + m.first_vertex,
                             md->vertices.begin() + m.first_vertex + m.vertex_count);
      out_md.indices.insert(out_md.indices.end(), md->indices.begin() + m.first_index,
                            md->indices.begin() + m.first_index + m.index_count);
      m.first_vertex = fv;
      m.first_index = fi;
      ++st.vertex_ranges_copied;
    } else {
      it->second.second = m;
      it->second.second.texture_id = old;
    }
    if (!packed[old]) continue;
    const Placement& p = placement[old];
    const double aw = atlases[p.atlas].width, ah = atlases[p.atlas].height;
    for (uint32_t v = 0; v < m.vertex_count; ++v) {
      scene::Vertex& vx = out_md.vertices[size_t{m.first_vertex} + v];
      vx.uv[0] = static_cast<float>((p.x + std::clamp(static_cast<double>(vx.uv[0]), 0.0, 1.0) * p.w) / aw);
      vx.uv[1] = static_cast<float>((p.y + std::clamp(static_cast<double>(vx.uv[1]), 0.0, 1.0) * p.h) / ah);
    }
  }

  std::vector<scene::TextureRecord> table(next);
  std::vector<uint32_t> colormap(next), out_sampling(next, 0);
  for (uint32_t id = 0; id < next; ++id) {
    const Source& s = source[id];
    if (s.atlas) {
      const Atlas& a = atlases[s.index];
      table[id] = {a.width, a.height, full_mip_count(a.width, a.height), static_cast<uint32_t>(a.format)};
      continue;
    }
    table[id] = (*records)[s.index];
    colormap[id] = (*colours)[s.index];
    out_sampling[id] = sampling[s.index];
  }

  // Texture files, a thread per core: kept ones hard-linked (copied across file systems), atlases built.
  std::atomic<uint64_t> done{0}, bytes_out{0}, bytes_in{0};
  std::atomic<uint32_t> cursor{0};
  std::mutex error_mutex;
  std::optional<Error> first_error;
  auto worker = [&]() {
    for (;;) {
      const uint32_t id = cursor.fetch_add(1);
      if (id >= next) return;
      {
        std::lock_guard lock(error_mutex);
        if (first_error) return;
      }
      Status st_one = ok_status();
      const fs::path to = scene::texture_path(tmp, TextureId(id));
      std::error_code e;
      fs::create_directories(to.parent_path(), e);
      if (!source[id].atlas) {
        const fs::path from = scene::texture_path(in, TextureId(source[id].index));
        fs::create_hard_link(from, to, e);
        if (e) {
          e.clear();
          fs::copy_file(from, to, fs::copy_options::overwrite_existing, e);
        }
        if (e) st_one = make_error(ErrorCode::kIo, from.string() + " -> " + to.string() + ": " + e.message());
        bytes_out += fs::file_size(from, e);
      } else {
        auto built = build_atlas_file(in, atlases[source[id].index], *records, placement);
        if (!built) {
          st_one = built.error();
        } else {
          colormap[id] = built->second;
          bytes_out += built->first.size();
          st_one = write_file(to, built->first);
        }
      }
      if (!st_one.ok()) {
        std::lock_guard lock(error_mutex);
        if (!first_error) first_error = st_one.error();
        return;
      }
      if (progress) progress(++done, next);
    }
  };
  const unsigned threads = opt.threads ? opt.threads : std::max(1u, std::thread::hardware_concurrency());
  {
    std::vector<std::jthread> pool;
    for (unsigned k = 0; k < std::min<unsigned>(threads, std::max<uint32_t>(next, 1)); ++k) pool.emplace_back(worker);
  }
  if (first_error) return *first_error;
  for (uint64_t t = 0; t < n; ++t)
    bytes_in += fs::file_size(scene::texture_path(in, TextureId(static_cast<uint32_t>(t))), ec);
  st.file_bytes_in = bytes_in;
  st.file_bytes_out = bytes_out;

  TS_TRY(scene::write_meshes(tmp, out_md));
  TS_TRY(scene::write_mesh_index(tmp, scene::build_mesh_index(out_md.meshes).view()));
  TS_TRY(scene::write_texture_table(tmp, table));
  TS_TRY(scene::write_colormap(tmp, colormap));
  if (has_sampling) TS_TRY(scene::write_sampling(tmp, out_sampling));
  if (!transforms.empty()) TS_TRY(scene::write_transforms(tmp, transforms));
  fs::copy_file(in / manifest->camera_path, tmp / manifest->camera_path, fs::copy_options::overwrite_existing, ec);
  if (ec) return make_error(ErrorCode::kIo, (in / manifest->camera_path).string() + ": cannot copy: " + ec.message());
  scene::Manifest m = *manifest;
  m.name = manifest->name + " (atlas " + std::to_string(opt.atlas_px) + ")";
  m.mesh_count = out_md.meshes.size();
  m.texture_count = next;
  TS_TRY(scene::write_manifest(tmp, m));

  TS_TRY(staged->commit());
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return st;
}

}  // namespace texstream::atlas
