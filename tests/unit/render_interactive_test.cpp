// The interactive mode's pure parts: fly camera maths, camera recording, the readout line, and the decoding of
// mesh-id pictures (the inverse of scene.frag's hash). No window, no GPU.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <set>

#include "texstream/render/frame/mip_math.hpp"
#include "texstream/render/frame/view_renderer.hpp"
#include "texstream/render/scene/gpu_structs.hpp"
#include "texstream/render/window/camera_recorder.hpp"
#include "texstream/render/window/fly_camera.hpp"
#include "texstream/render/window/interactive_session.hpp"

using namespace texstream;
using namespace texstream::render;

TEST(FlyCamera, WMovesAlongTheViewAndDMovesRight) {
  FlyCamera c(CameraPose{{392000.0, 5820000.0, 50.0}, 0, 0});  // looking north
  FlyInput in;
  in.forward = true;
  c.update(in, 1.0);
  EXPECT_NEAR(c.pose().position[1], 5820000.0 + FlyCamera::kSpeedMps, 1e-6);
  EXPECT_NEAR(c.pose().position[0], 392000.0, 1e-6);
  in = {};
  in.right = true;
  in.fast = true;
  c.update(in, 0.5);
  EXPECT_NEAR(c.pose().position[0], 392000.0 + FlyCamera::kSpeedMps * FlyCamera::kFastFactor * 0.5, 1e-6);
  in = {};
  in.up = true;
  c.update(in, 1.0);
  EXPECT_NEAR(c.pose().position[2], 50.0 + FlyCamera::kSpeedMps, 1e-6);
}

TEST(FlyCamera, MouseTurnsAndPitchStopsShortOfVertical) {
  FlyCamera c(CameraPose{{0, 0, 0}, 350, 0});
  FlyInput in;
  in.mouse_dx_px = 20.0 / FlyCamera::kDegreesPerPixel;  // +20 degrees: wraps past north
  in.mouse_dy_px = -1e6;                                // far up
  c.update(in, 0.0);
  EXPECT_NEAR(c.pose().yaw_deg, 10.0, 1e-9);
  EXPECT_DOUBLE_EQ(c.pose().pitch_deg, FlyCamera::kMaxPitchDeg);
  in = {};
  in.forward = true;
  const CameraPose before = c.pose();
  c.update(in, std::nan(""));  // a broken clock moves nothing
  c.update(in, -1.0);
  EXPECT_EQ(c.pose().position[1], before.position[1]);
}

TEST(CameraRecorder, WritesAPathThatLoadsBack) {
  const auto file =
      std::filesystem::temp_directory_path() / ("texstream_rec_" + std::to_string(::getpid()) + "/path.txt");
  CameraRecorder r(file);
  r.add(0.0, CameraPose{{1, 2, 3}, 0, 0});  // not recording: ignored
  r.start();
  r.add(0.0, CameraPose{{392000.5, 5820000.25, 40}, 10, -5});
  r.add(0.5, CameraPose{{392010.5, 5820000.25, 40}, 20, -5});
  r.add(0.4, CameraPose{{392020.5, 5820000.25, 40}, 30, -5});  // time never goes backwards
  ASSERT_TRUE(r.stop().ok());
  auto path = CameraPath::load(file);
  ASSERT_TRUE(path.ok()) << path.error().message;
  ASSERT_EQ(path->keys().size(), 3u);
  EXPECT_DOUBLE_EQ(path->keys()[0].pose.position[0], 392000.5);
  EXPECT_DOUBLE_EQ(path->keys()[2].time_s, 0.5);
  std::filesystem::remove_all(file.parent_path());
}

TEST(InteractiveReadout, NamesEveryFigureAndSaysNaWhenAbsent) {
  InteractiveReadout r;
  r.frame_latency_ms = 12.34;
  r.textures_resident = 5;
  r.texture_count = 40;
  r.load_size_mb = 16.0;
  const std::string line = format_readout(r, 4.5);
  EXPECT_NE(line.find("latency 12.3 ms"), std::string::npos) << line;
  EXPECT_NE(line.find("stream 4.50 MB/s"), std::string::npos) << line;
  EXPECT_NE(line.find("cache 5/40"), std::string::npos) << line;
  EXPECT_NE(line.find("s 16.00 MB"), std::string::npos) << line;
  EXPECT_NE(line.find("b n/a"), std::string::npos) << line;
}

TEST(MeshIdView, DecodeInvertsTheShaderHash) {
  std::set<uint32_t> codes;
  for (uint32_t id : {0u, 1u, 2u, 255u, 4095u, 1000000u, (1u << 24) - 2}) {
    const uint32_t code = ((id + 1u) * gpu::kMeshIdHashMul) & 0xffffffu;  // scene.frag's mesh_id_colour
    codes.insert(code);
    EXPECT_EQ(decode_mesh_id(code & 0xff, (code >> 8) & 0xff, code >> 16), static_cast<int64_t>(id));
  }
  EXPECT_EQ(codes.size(), 7u);
  EXPECT_EQ(decode_mesh_id(0, 0, 0), -1);  // the clear colour: no mesh
}

TEST(MipMath, RoundingNoiseDoesNotDoubleTheTaps) {
  // An isotropic footprint whose axes differ in the last bits must stay one tap (and its level), not two.
  const float p = 2.828427f;
  const auto r = anisotropic_lod(p, 0, 0, p * (1.0f + 1e-6f), 16);
  EXPECT_FLOAT_EQ(r.taps, 1.0f);
  EXPECT_NEAR(r.lod, 1.5f, 1e-4f);
  // Non-finite footprints ask for the coarsest level instead of producing NaN.
  const auto inf = anisotropic_lod(INFINITY, 0, 0, 1, 16);
  EXPECT_GT(inf.lod, 60.0f);
  const auto nan = anisotropic_lod(NAN, 0, 0, 1, 16);
  EXPECT_FALSE(std::isnan(nan.lod));
}
