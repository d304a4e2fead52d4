// The stream client's statistics have one field list (stream_stats.hpp): the text texstream-chaos reads, the
// JSON of summary.json and the reading of the text must all carry every field, by the same names.
#include <gtest/gtest.h>

#include <string>

#include "texstream/stream/stream_stats.hpp"

namespace {

using namespace texstream::stream;

StreamStats distinct_counters() {
  StreamStats s;
  uint64_t v = 1000;
  for (const StreamCounterField& f : kStreamCounters) s.*f.member = v++;
  s.completions_failed[0] = 3;
  s.completions_failed[2] = 4;
  s.server_state = StreamServerState::kBackingOff;
  return s;
}

TEST(StreamStatsText, EveryFieldIsWrittenAndReadBackByTheSameList) {
  const StreamStats s = distinct_counters();
  IpcTimeHistogram ipc;
  ipc.add(20'000);
  ipc.add(2'500'000);
  const std::string text = format_stream_stats(s, ipc);
  auto read = parse_stream_stats(text, "stats");
  ASSERT_TRUE(read.ok()) << read.error().message;
  for (const StreamCounterField& f : kStreamCounters) EXPECT_EQ(read->stats.*f.member, s.*f.member) << f.name;
  EXPECT_EQ(read->stats.completions_failed[0], 7u);
  EXPECT_EQ(read->server_state, "backing off");
  const IpcSummary want = IpcSummary::of(ipc);
  for (const IpcField& f : kIpcFields) EXPECT_DOUBLE_EQ(read->ipc.*f.member, want.*f.member) << f.name;
  EXPECT_EQ(read->ipc.frames, 2.0);
  EXPECT_EQ(read->ipc.frames_over_1ms, 1.0);
}

TEST(StreamStatsText, TheJsonHoldsTheSameFields) {
  const StreamStats s = distinct_counters();
  IpcTimeHistogram ipc;
  ipc.add(50'000);
  const nlohmann::json j = stream_stats_json(s, ipc);
  for (const StreamCounterField& f : kStreamCounters) {
    ASSERT_TRUE(j.contains(std::string(f.name))) << f.name;
    EXPECT_EQ(j[std::string(f.name)].get<uint64_t>(), s.*f.member) << f.name;
  }
  for (const IpcField& f : kIpcFields) EXPECT_TRUE(j.contains(std::string(f.name))) << f.name;
  EXPECT_EQ(j["completions_failed"].get<uint64_t>(), 7u);
  EXPECT_EQ(j["server_state"].get<std::string>(), "backing off");
  EXPECT_EQ(j.size(), kStreamCounters.size() + kIpcFields.size() + 2);
}

TEST(StreamStatsText, AnUnknownKeyOrABadNumberIsNamedWithItsLine) {
  auto unknown = parse_stream_stats("requests_sent 4\nrequests_snet 5\n", "/tmp/chaos.stats");
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.error().message.find("/tmp/chaos.stats:2"), std::string::npos) << unknown.error().message;
  EXPECT_NE(unknown.error().message.find("requests_snet"), std::string::npos);
  auto bad = parse_stream_stats("ipc_p99_us 12x\n", "f");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("f:1: 'ipc_p99_us' has no number ('12x')"), std::string::npos)
      << bad.error().message;
  auto negative = parse_stream_stats("server_deaths -1\n", "f");
  ASSERT_FALSE(negative.ok());
  EXPECT_NE(negative.error().message.find("negative"), std::string::npos);
}

}  // namespace
