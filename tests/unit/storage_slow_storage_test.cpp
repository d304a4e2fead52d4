// Slow-storage emulation: the per-read plan is a pure function of the seed and the read (determinism), its
// draws have the configured rates, and out-of-range parameters are refused naming the key.
#include <gtest/gtest.h>

#include "texstream/server/storage/slow_storage.hpp"

namespace texstream::server {
namespace {

SlowStorageParams noisy() {
  SlowStorageParams p;
  p.latency_ms = 20;
  p.jitter_ms = 10;
  p.stall_probability = 0.1;
  p.stall_ms = 500;
  p.failure_rate = 0.05;
  p.seed = 1234;
  return p;
}

TEST(SlowStorage, SameSeedSameReadsSamePlans) {
  const SlowStorageParams p = noisy();
  for (uint64_t i = 0; i < 200; ++i) {
    const SlowReadPlan a = plan_slow_read(p, "textures/000/00000001.dds", i * 4096, 4096, i % 3);
    const SlowReadPlan b = plan_slow_read(p, "textures/000/00000001.dds", i * 4096, 4096, i % 3);
    EXPECT_EQ(a.delay_ms, b.delay_ms);
    EXPECT_EQ(a.fails, b.fails);
    EXPECT_EQ(a.stalled, b.stalled);
  }
}

TEST(SlowStorage, AnotherSeedOrAttemptDrawsAnew) {
  SlowStorageParams p = noisy();
  SlowStorageParams q = p;
  q.seed = 4321;
  int differ_seed = 0, differ_attempt = 0;
  for (uint64_t i = 0; i < 100; ++i) {
    differ_seed += plan_slow_read(p, "a", i, 64, 0).delay_ms != plan_slow_read(q, "a", i, 64, 0).delay_ms;
    differ_attempt += plan_slow_read(p, "a", i, 64, 0).delay_ms != plan_slow_read(p, "a", i, 64, 1).delay_ms;
  }
  EXPECT_GT(differ_seed, 90);
  EXPECT_GT(differ_attempt, 90);
}

TEST(SlowStorage, DrawsHaveTheConfiguredRates) {
  const SlowStorageParams p = noisy();
  constexpr int kReads = 20000;
  int stalls = 0, failures = 0;
  double min_delay = 1e9, max_plain = 0;
  for (int i = 0; i < kReads; ++i) {
    const SlowReadPlan plan = plan_slow_read(p, "textures/x.dds", uint64_t(i) * 100, 100, 0);
    stalls += plan.stalled;
    failures += plan.fails;
    min_delay = std::min(min_delay, plan.delay_ms);
    if (!plan.stalled) max_plain = std::max(max_plain, plan.delay_ms);
  }
  EXPECT_NEAR(double(stalls) / kReads, 0.1, 0.01);
  EXPECT_NEAR(double(failures) / kReads, 0.05, 0.008);
  EXPECT_GE(min_delay, 20.0);
  EXPECT_LT(max_plain, 30.0);  // latency + jitter < 20 + 10
  EXPECT_GT(max_plain, 29.0);
}

TEST(SlowStorage, ZeroParametersMeanNoDelayAndNoFailure) {
  const SlowStorageParams p;
  for (uint64_t i = 0; i < 100; ++i) {
    const SlowReadPlan plan = plan_slow_read(p, "f", i, 10, 0);
    EXPECT_EQ(plan.delay_ms, 0.0);
    EXPECT_FALSE(plan.fails);
  }
}

TEST(SlowStorage, OutOfRangeParametersNameTheirKey) {
  SlowStorageParams p;
  p.failure_rate = 1.5;
  auto s = validate(p);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("storage.slow_failure_rate"), std::string::npos);
  p = SlowStorageParams{};
  p.latency_ms = -1;
  EXPECT_FALSE(validate(p).ok());
}

}  // namespace
}  // namespace texstream::server
