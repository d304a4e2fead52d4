// texstream-bench plan [--quick] [--scene DIR] [--meshes N] [--views N]
//
// The CPU part of planning a city frame (render/frame/frame_plan.cpp), on the renderer's own BroadPhase: for
// views along a bird's-eye flight over the scene, the wide-frustum query, then the viewport split and the
// dropping of meshes that cover no pixel centre. Measured both ways in this run, alternating per view:
//   two_pass   BroadPhase::split_by_viewport, then BroadPhase::drop_unsampled (each reads every record)
//   fused      BroadPhase::split_and_drop_unsampled (one pass on every core: what a frame runs)
// Both must give the same ids in the same order and the same runs (mismatches counts the views where not).
// The scene is a synthetic city in memory (blocks of houses: four fronts and a roof each, ids in build order)
// unless --scene names a scene folder, whose meshes.bin is read (its textures are not).
// Ends with `summary: meshes=... ids_per_view=... query_ms=... two_pass_ms=... fused_ms=... fused_speedup=...
// mismatches=...` (the times are medians over the views; docs/design/render_stack.md, *Planning a city frame*).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "bench_registry.hpp"
#include "bench_util.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/render/scene/broad_phase.hpp"
#include "texstream/render/scene/camera.hpp"
#include "texstream/render/scene/scene_data.hpp"

namespace texstream::bench {
namespace {

struct PlanOptions {
  bool quick = false;
  std::string scene;
  size_t meshes = 300000;
  int views = 0;  // 0: the mode's (48 quick, 192 full)
};

// A city of square blocks of houses, built row by row (ids in build order, as a generator or an importer
// writes them): each house four fronts and a roof, 6-20 m wide, 6-40 m high, on a 2 km-scale grid.
std::vector<scene::MeshRecord> synthetic_city(size_t count) {
  std::vector<scene::MeshRecord> meshes;
  meshes.reserve(count);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> width(6, 20), height(6, 40);
  const auto houses = static_cast<size_t>(std::ceil(static_cast<double>(count) / 5.0));
  const auto side = static_cast<size_t>(std::ceil(std::sqrt(static_cast<double>(houses))));
  for (size_t h = 0; h < houses && meshes.size() < count; ++h) {
    const double x = 392000.0 + static_cast<double>(h % side) * 25.0,
                 y = 5820000.0 + static_cast<double>(h / side) * 25.0;
    const float w = width(rng), d = width(rng), z = height(rng);
    auto add = [&](double ox, double oy, double oz, std::array<float, 3> lo, std::array<float, 3> hi) {
      if (meshes.size() >= count) return;
      scene::MeshRecord m{};
      m.origin[0] = ox;
      m.origin[1] = oy;
      m.origin[2] = oz;
      for (int a = 0; a < 3; ++a) {
        m.bounds_min[a] = lo[static_cast<size_t>(a)];
        m.bounds_max[a] = hi[static_cast<size_t>(a)];
      }
      m.texture_id = static_cast<uint32_t>(meshes.size());
      meshes.push_back(m);
    };
    add(x, y, 0, {0, 0, 0}, {w, 0, z});  // the four fronts: planar boxes
    add(x, y + static_cast<double>(d), 0, {0, 0, 0}, {w, 0, z});
    add(x, y, 0, {0, 0, 0}, {0, d, z});
    add(x + static_cast<double>(w), y, 0, {0, 0, 0}, {0, d, z});
    add(x, y, static_cast<double>(z), {0, 0, 0}, {w, d, 0});  // the roof
  }
  return meshes;
}

int run_plan_bench(const PlanOptions& o) {
  std::vector<scene::MeshRecord> own;
  std::span<const scene::MeshRecord> meshes;
  std::optional<render::SceneData> scene;
  if (!o.scene.empty()) {
    auto opened = render::SceneData::open(o.scene);
    if (!opened) {
      std::fprintf(stderr, "plan bench: --scene %s: %s\n", o.scene.c_str(), opened.error().message.c_str());
      return 2;
    }
    scene.emplace(std::move(*opened));
    meshes = scene->mesh_records();
  } else {
    own = synthetic_city(o.meshes);
    meshes = own;
  }
  if (meshes.empty()) {
    std::fprintf(stderr, "plan bench: the scene has no meshes\n");
    return 2;
  }
  const render::BroadPhase bp(meshes);
  // The flight: along the diagonal of the meshes' ground extent, 150 m up, looking ahead and 25 degrees down,
  // turning left and right as it goes.
  double lo[2] = {1e300, 1e300}, hi[2] = {-1e300, -1e300};
  for (const auto& m : meshes) {
    for (int a = 0; a < 2; ++a) {
      lo[a] = std::min(lo[a], m.origin[a]);
      hi[a] = std::max(hi[a], m.origin[a]);
    }
  }
  const int views = o.views > 0 ? o.views : (o.quick ? 48 : 192);
  const double heading = std::atan2(hi[1] - lo[1], hi[0] - lo[0]) * 180.0 / M_PI;
  const glm::mat4 proj = render::perspective_reversed_z(60, 16.0 / 9.0, 0.5, 3000.0);
  const glm::mat4 wide = render::perspective_reversed_z(90, 16.0 / 9.0, 0.5, 3000.0);
  std::vector<double> query_ms, two_ms, fused_ms, ids_per_view;
  int mismatches = 0;
  std::vector<uint32_t> ids, two, one;
  for (int v = 0; v < views; ++v) {
    const double t = (static_cast<double>(v) + 0.5) / static_cast<double>(views);
    const std::array<double, 3> cam{lo[0] + t * (hi[0] - lo[0]), lo[1] + t * (hi[1] - lo[1]), 150.0};
    const double yaw = 90.0 - heading + 40.0 * std::sin(t * 12.0);  // forward_from_angles: 0 = north, clockwise
    const glm::mat4 view = render::view_rotation(render::forward_from_angles(yaw, -25));
    const render::SampleGrid main{proj * view, 1920, 1080, render::SampleGrid::margin_px_for(8)};
    const render::SampleGrid wide_grid{wide * view, 960, 540, render::SampleGrid::margin_px_for(8)};
    const auto viewport = render::Frustum::from_matrix(proj * view);
    Stopwatch clock;
    bp.query(render::Frustum::from_matrix(wide * view), cam, ids);
    query_ms.push_back(clock.seconds() * 1e3);
    ids_per_view.push_back(static_cast<double>(ids.size()));
    render::ViewportSplit a{}, b{};
    for (int k = 0; k < 2; ++k) {
      if ((k == 0) == (v % 2 == 0)) {
        two = ids;
        clock.reset();
        a = bp.drop_unsampled(main, wide_grid, cam, two, bp.split_by_viewport(viewport, cam, two));
        two_ms.push_back(clock.seconds() * 1e3);
      } else {
        one = ids;
        clock.reset();
        b = bp.split_and_drop_unsampled(viewport, main, wide_grid, cam, one);
        fused_ms.push_back(clock.seconds() * 1e3);
      }
    }
    if (one != two || a.main_end != b.main_end) ++mismatches;
  }
  const double q = percentile(query_ms, 50), p2 = percentile(two_ms, 50), p1 = percentile(fused_ms, 50);
  std::printf("plan bench: %zu meshes (%s), %d views, median %.0f ids in the wide frustum\n", meshes.size(),
              o.scene.empty() ? "synthetic city" : o.scene.c_str(), views, percentile(ids_per_view, 50));
  std::printf("  query (wide frustum)           median %8.3f ms\n", q);
  std::printf("  split, then drop (two passes)  median %8.3f ms  p95 %8.3f ms\n", p2, percentile(two_ms, 95));
  std::printf("  split and drop in one pass     median %8.3f ms  p95 %8.3f ms\n", p1, percentile(fused_ms, 95));
  Summary()
      .add("meshes", static_cast<double>(meshes.size()))
      .add("ids_per_view", std::round(percentile(ids_per_view, 50)))
      .add("query_ms", q)
      .add("two_pass_ms", p2)
      .add("fused_ms", p1)
      .add("fused_speedup", p1 > 0 ? p2 / p1 : 0.0)
      .add("mismatches", mismatches)
      .print();
  return mismatches == 0 ? 0 : 1;
}

std::function<int()> define_plan(CLI::App& app) {
  auto o = std::make_shared<PlanOptions>();
  app.add_flag("--quick", o->quick, "48 views (default 192)");
  app.add_option("--scene", o->scene, "scene folder whose meshes to use (default: a synthetic city in memory)");
  app.add_option("--meshes", o->meshes, "meshes of the synthetic city (default 300000)")
      ->check(CLI::Range(1, 50000000));
  app.add_option("--views", o->views, "views along the flight (default: the mode's)")->check(CLI::Range(1, 100000));
  return [o] { return run_plan_bench(*o); };
}

}  // namespace

TEXSTREAM_BENCH_COMMAND(plan, "the CPU part of planning a city frame: viewport split and unsampled meshes",
                        define_plan);

}  // namespace texstream::bench
