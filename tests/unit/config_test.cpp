// Configuration: every key parses, unknown keys and bad values are errors naming the key, overrides apply in
// order, and the shipped config/default.toml and docs/config.md agree with the code.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "texstream/common/config.hpp"

namespace texstream {
namespace {

std::string error_of(const std::string& toml, std::vector<std::string> overrides = {}) {
  auto c = parse_config(toml, "test.toml", overrides);
  return c.ok() ? std::string() : c.error().message;
}

TEST(Config, DefaultsValidate) {
  auto c = parse_config("", "empty", {});
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->stream.tau, 150.0);  // seed 000 Table 2
  EXPECT_EQ(c->render.device, "llvmpipe");
}

TEST(Config, ParsesEveryKindOfValue) {
  auto c =
      parse_config("[render]\nwidth_px = 320\nvalidation = true\nfov_y_deg = 45\n[scene]\ndir = \"x/y\"\n", "t", {});
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->render.width_px, 320);
  EXPECT_TRUE(c->render.validation);
  EXPECT_EQ(c->render.fov_y_deg, 45.0);  // an integer is accepted for a float key
  EXPECT_EQ(c->scene.dir, "x/y");
}

TEST(Config, UnknownKeysAndSectionsAreErrorsNamingThem) {
  EXPECT_NE(error_of("[render]\nwidht_px = 3\n").find("'render.widht_px'"), std::string::npos);
  EXPECT_NE(error_of("[rendr]\nwidth_px = 3\n").find("'rendr'"), std::string::npos);
  EXPECT_NE(error_of("top = 1\n").find("'top'"), std::string::npos);
}

TEST(Config, OutOfRangeAndWrongTypeAreErrorsNamingTheKey) {
  EXPECT_NE(error_of("[render]\nwidth_px = 0\n").find("'render.width_px'"), std::string::npos);
  EXPECT_NE(error_of("[render]\nwidth_px = \"wide\"\n").find("'render.width_px'"), std::string::npos);
  EXPECT_NE(error_of("[stream]\ntau = -1.0\n").find("'stream.tau'"), std::string::npos);
  EXPECT_NE(error_of("[stream]\ntau = nan\n").find("'stream.tau'"), std::string::npos);
  EXPECT_NE(error_of("[render]\nvalidation = 1\n").find("'render.validation'"), std::string::npos);
  EXPECT_NE(error_of("[render]\nwidth_px = 3.5\n").find("'render.width_px'"), std::string::npos);
}

TEST(Config, RelationsBetweenKeysAreValidated) {
  EXPECT_NE(error_of("[protocol]\nrequest_ring_capacity = 1000\n").find("'protocol.request_ring_capacity'"),
            std::string::npos);
  EXPECT_NE(error_of("[cache]\nformat = \"dxt5\"\n").find("'cache.format'"), std::string::npos);
  EXPECT_NE(error_of("[render]\nnear_m = 100.0\nfar_m = 10.0\n").find("'render.near_m'"), std::string::npos);
  EXPECT_NE(error_of("[cache]\nlayer_extent_px = 1000\n").find("'cache.layer_extent_px'"), std::string::npos);
  // A slot smaller than the largest mip a layer could hold is no longer refused here: what matters is the scene's
  // largest mip, which the stream client checks at start (it names the texture).
  EXPECT_TRUE(parse_config("[protocol]\nstaging_slot_bytes = 4096\n", "t", {}).ok());
  // A standalone server serves a name: server.spawn = false needs protocol.segment_name.
  EXPECT_NE(error_of("[server]\nspawn = false\n").find("'server.spawn'"), std::string::npos);
  EXPECT_TRUE(parse_config("[server]\nspawn = false\n[protocol]\nsegment_name = \"ts-city\"\n", "t", {}).ok());
}

// These two were checked only when a Renderer was built (after the scene load); every program that reads a
// config now refuses them at parse time, naming the key.
TEST(Config, RenderModesThatExcludeEachOtherAreRefused) {
  const std::string pairs = error_of("[render]\nwindow = true\nfeedback_pairs = true\n");
  EXPECT_NE(pairs.find("'render.feedback_pairs'"), std::string::npos) << pairs;
  EXPECT_NE(pairs.find("render.window"), std::string::npos) << pairs;
  EXPECT_TRUE(parse_config("[render]\nfeedback_pairs = true\n", "t", {}).ok());
  EXPECT_TRUE(parse_config("[render]\nwindow = true\n", "t", {}).ok());

  const std::string baselines = error_of("", {"render.preload_all=true", "render.blocking_loads=true"});
  EXPECT_NE(baselines.find("'render.preload_all'"), std::string::npos) << baselines;
  EXPECT_NE(baselines.find("render.blocking_loads"), std::string::npos) << baselines;
  EXPECT_TRUE(parse_config("", "t", {"render.preload_all=true"}).ok());
  EXPECT_TRUE(parse_config("", "t", {"render.blocking_loads=true"}).ok());

  // render.load_wanted_before_drawing: another way to make reference frames and another load-before-drawing
  // mode, and it reads what the frame wants from the feedback pass.
  const std::string wanted = "render.load_wanted_before_drawing=true";
  for (const char* other : {"render.preload_all=true", "render.blocking_loads=true", "render.feedback=false",
                            "render.feedback_pairs=true"}) {
    const std::string e = error_of("", {wanted, other});
    EXPECT_NE(e.find("'render.load_wanted_before_drawing'"), std::string::npos) << other << ": " << e;
    const std::string other_key = std::string(other).substr(0, std::string(other).find('='));
    EXPECT_NE(e.find(other_key), std::string::npos) << other << ": " << e;
  }
  EXPECT_TRUE(parse_config("", "t", {wanted}).ok());
}

// Each fixed-value key reads its names from its enum's one table: a name outside it is refused naming the key
// and listing the names it takes (before: five hand-written lists, two of which did not give the list).
TEST(Config, AChoiceKeyTakesOnlyItsNames) {
  struct Case {
    const char* key;
    const char* bad;
    const char* allowed;
  };
  for (const Case& c : {Case{"controller.mode", "sometimes", "auto, seed, adaptive, none or fixed"},
                        Case{"render.debug_view", "depth", "none, mip, weight, mesh_id, page_level or page_residency"},
                        Case{"cache.format", "dxt5", "auto, rgba8, bc1, bc3 or bc7"},
                        Case{"server.log_level", "loud", "trace, debug, info, warn or error"},
                        Case{"server.cache_policy", "mru", "level or lru"},
                        Case{"storage.disk_cache_policy", "level", "lru or fifo"}}) {
    const std::string e = error_of("", {std::string(c.key) + "=" + c.bad});
    EXPECT_NE(e.find("'" + std::string(c.key) + "'"), std::string::npos) << e;
    EXPECT_NE(e.find(std::string("must be ") + c.allowed + ", not '" + c.bad + "'"), std::string::npos) << e;
    const std::string wrong_type = error_of("", {std::string(c.key) + "=3"});
    EXPECT_NE(wrong_type.find("'" + std::string(c.key) + "'"), std::string::npos) << wrong_type;
  }
  // The same check in a file, and the enum each name gives.
  EXPECT_NE(error_of("[controller]\nmode = \"sometimes\"\n").find("'controller.mode'"), std::string::npos);
  auto c = parse_config("[controller]\nmode = \"fixed\"\n[cache]\nformat = \"bc1\"\n", "t",
                        {"render.debug_view=mesh_id", "server.log_level=\"warn\"", "server.cache_policy=lru",
                         "storage.disk_cache_policy=fifo"});
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->controller.mode, ControllerMode::kFixed);
  EXPECT_EQ(c->cache.format, CacheFormat::kBc1);
  EXPECT_EQ(c->render.debug_view, DebugView::kMeshId);
  EXPECT_EQ(c->server.log_level, LogLevel::kWarn);
  EXPECT_EQ(c->server.cache_policy, RamCachePolicy::kLru);
  EXPECT_EQ(c->storage.disk_cache_policy, DiskCachePolicy::kFifo);
  // Written back by name, and read back equal (the spawned server gets this text).
  const std::string toml = to_toml(*c);
  EXPECT_NE(toml.find("mode = \"fixed\""), std::string::npos) << toml;
  auto back = parse_config(toml, "roundtrip", {});
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(to_toml(*back), toml);
}

TEST(Config, AChoiceOutsideItsTableIsRefusedByValidate) {
  Config c;
  c.render.debug_view = static_cast<DebugView>(7);
  const Status s = c.validate();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("'render.debug_view'"), std::string::npos) << s.error().message;
}

// Each choice's table is what the documentation shows: every name with its doc, in table order.
TEST(Config, AChoiceKeyIsDocumentedFromItsTable) {
  EXPECT_EQ(choice_names<CacheFormat>(), "auto, rgba8, bc1, bc3 or bc7");
  EXPECT_EQ(choice_docs<CacheFormat>(), "auto (each texture's own), rgba8, bc1, bc3 or bc7");
  const std::string doc = config_reference_markdown();
  EXPECT_NE(doc.find("Texel format of the GPU cache: auto (each texture's own), rgba8, bc1, bc3 or bc7"),
            std::string::npos);
  EXPECT_NE(doc.find("| `controller.mode` | string | name | `\"auto\"` | auto, seed, adaptive, none or fixed |"),
            std::string::npos);
  EXPECT_EQ(cache_texel_format(CacheFormat::kAuto), std::nullopt);  // every texture in its own format
  EXPECT_EQ(cache_texel_format(CacheFormat::kRgba8), TexelFormat::kRgba8);
  EXPECT_EQ(choice_name(DebugView::kMeshId), "mesh_id");
  EXPECT_EQ(choice_from_name<DebugView>("weight"), DebugView::kWeight);
  EXPECT_FALSE(choice_from_name<DebugView>("Weight").has_value());
}

// A segment name that no shared-memory object can have is refused naming the key. Before, the renderer failed
// with "cannot create shared segment 'a/b': Invalid argument", and a standalone server on it waited for ever.
TEST(Config, ASegmentNameNoSharedMemoryObjectCanHaveIsRefused) {
  const std::string slash = error_of("[protocol]\nsegment_name = \"city/a\"\n");
  EXPECT_NE(slash.find("'protocol.segment_name'"), std::string::npos) << slash;
  EXPECT_NE(slash.find("contains '/'"), std::string::npos) << slash;
  const std::string long_name = error_of("[protocol]\nsegment_name = \"" + std::string(256, 'x') + "\"\n");
  EXPECT_NE(long_name.find("256 bytes long"), std::string::npos) << long_name;
  EXPECT_NE(error_of("[protocol]\nsegment_name = \"..\"\n").find("'protocol.segment_name'"), std::string::npos);
  EXPECT_TRUE(parse_config("[protocol]\nsegment_name = \"" + std::string(255, 'x') + "\"\n", "t", {}).ok());
  EXPECT_FALSE(segment_name_problem("ts-city.1_a").has_value());
  EXPECT_TRUE(segment_name_problem("").has_value());
  EXPECT_TRUE(segment_name_problem(std::string_view("a\0b", 3)).has_value());
}

TEST(Config, MalformedTomlNamesFileAndLine) {
  const std::string e = error_of("[render]\nwidth_px = = 3\n");
  EXPECT_NE(e.find("test.toml:2"), std::string::npos) << e;
}

TEST(Config, OverridesApplyInOrderAndAreChecked) {
  auto c = parse_config("[render]\nframes = 5\n", "t",
                        {"render.frames=7", "render.frames=9", "scene.dir=abc/def", "render.validation=true",
                         "protocol.segment_name=1234"});
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->render.frames, 9);
  EXPECT_EQ(c->scene.dir, "abc/def");
  EXPECT_TRUE(c->render.validation);
  EXPECT_EQ(c->protocol.segment_name, "1234");  // a string key keeps a numeric-looking value as text
  EXPECT_NE(error_of("", {"render.nope=1"}).find("'render.nope'"), std::string::npos);
  EXPECT_NE(error_of("", {"render.frames"}).find("render.frames"), std::string::npos);
  EXPECT_NE(error_of("", {"render.frames=-3"}).find("'render.frames'"), std::string::npos);
}

TEST(Config, TomlRoundTrip) {
  auto c = parse_config("", "t", {"render.width_px=333", "stream.tau=12.25", "scene.dir=with \"quote\""});
  ASSERT_TRUE(c.ok()) << c.error().message;
  auto back = parse_config(to_toml(c.value()), "roundtrip", {});
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(to_toml(back.value()), to_toml(c.value()));
  EXPECT_EQ(back->render.width_px, 333);
  EXPECT_EQ(back->stream.tau, 12.25);
  EXPECT_EQ(back->scene.dir, "with \"quote\"");
}

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(Config, ShippedProfilesParse) {
  for (const char* name : {"default.toml", "lavapipe.toml", "gpu.toml", "test.toml"}) {
    auto c = load_config(std::string(TEXSTREAM_SOURCE_DIR) + "/config/" + name, {});
    EXPECT_TRUE(c.ok()) << name << ": " << (c.ok() ? "" : c.error().message);
  }
}

TEST(Config, DefaultTomlStatesTheCodeDefaults) {
  auto shipped = load_config(std::string(TEXSTREAM_SOURCE_DIR) + "/config/default.toml", {});
  ASSERT_TRUE(shipped.ok()) << shipped.error().message;
  EXPECT_EQ(to_toml(shipped.value()), to_toml(Config{}))
      << "config/default.toml and the defaults in config.hpp disagree; regenerate with texstream-config --defaults";
}

TEST(Config, ReferenceDocIsCurrent) {
  const std::string doc = slurp(std::string(TEXSTREAM_SOURCE_DIR) + "/docs/config.md");
  EXPECT_NE(doc.find(config_reference_markdown()), std::string::npos)
      << "docs/config.md is stale; regenerate with: build/bin/texstream-config --reference";
}

// Found by fuzz_config: a control character in a string value passed validation but was written raw, and
// toml++ refuses to read that back.
TEST(Config, ControlCharactersInStringsRoundTrip) {
  Config c;
  c.scene.dir = std::string("form\ffeed, tab\t, bell\x07, del\x7f, nul") + '\0' + "end";
  c.render.camera_path = "line\nbreak";
  auto back = parse_config(to_toml(c), "roundtrip", {});
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back->scene.dir, c.scene.dir);
  EXPECT_EQ(back->render.camera_path, c.render.camera_path);
}

// protocol.staging_slot_bytes = 0 sizes the slots for the scene's largest mip; a set value is kept.
TEST(Config, AutoStagingSlotsHoldTheLargestMip) {
  ProtocolConfig p;  // auto slot size
  p.staging_slot_count = 32;
  EXPECT_EQ(effective_staging(p, 1000).slot_bytes, kMinAutoSlotBytes);  // small scenes: 64 KiB
  EXPECT_EQ(effective_staging(p, 1000).slot_count, 32u);
  // 2048 x 1024 RGBA8 (8 MiB): 32 slots of 8 MiB = 256 MiB, within the cap.
  EXPECT_EQ(effective_staging(p, 8u << 20).slot_bytes, 8u << 20);
  EXPECT_EQ(effective_staging(p, 8u << 20).slot_count, 32u);
  EXPECT_EQ(effective_staging(p, (8u << 20) + 1).slot_bytes, (8u << 20) + 4096);  // 4 KiB aligned
  // 4096² RGBA8 (64 MiB): the pool is held to kMaxAutoStagingBytes by fewer slots.
  const StagingShape big = effective_staging(p, 64u << 20);
  EXPECT_EQ(big.slot_bytes, 64u << 20);
  EXPECT_EQ(big.slot_count * big.slot_bytes, kMaxAutoStagingBytes);
  // Larger than the protocol allows: capped (such levels are then refused, with a warning at start).
  EXPECT_EQ(effective_staging(p, 1u << 30).slot_bytes, 64u << 20);
  p.staging_slot_bytes = 4096;
  EXPECT_EQ(effective_staging(p, 8u << 20).slot_bytes, 4096u);
  EXPECT_EQ(effective_staging(p, 8u << 20).slot_count, 32u);
}

// The segment is backed at creation: auto slots take at most half of /dev/shm's free space (a container's
// 64 MiB /dev/shm holds the default 1024 slots of 64 KiB only in part), never fewer than 4; set slots are kept.
TEST(Config, AutoStagingSlotsLeaveHalfOfDevShmFree) {
  ProtocolConfig p;
  ASSERT_EQ(p.staging_slot_count, 1024);
  EXPECT_EQ(effective_staging(p, 1000).slot_count, 1024u);  // 64 MiB of 64 KiB slots
  EXPECT_EQ(effective_staging(p, 1000, 64ull << 20).slot_count, 512u);
  EXPECT_EQ(effective_staging(p, 1000, 64ull << 20).slot_bytes, kMinAutoSlotBytes);
  EXPECT_EQ(effective_staging(p, 1000, 1ull << 20).slot_count, 8u);
  EXPECT_EQ(effective_staging(p, 1000, 256ull << 10).slot_count, 4u);
  p.staging_slot_bytes = 65536;
  EXPECT_EQ(effective_staging(p, 1000, 1ull << 20).slot_count, 1024u) << "a set slot size is the user's choice";
}

}  // namespace
}  // namespace texstream
