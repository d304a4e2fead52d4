// server.rate_limit_mb_s's token bucket, on a fake clock.
#include <gtest/gtest.h>

#include "texstream/server/storage/token_bucket.hpp"

namespace texstream::server {
namespace {

constexpr uint64_t kMs = 1'000'000;  // ns

TEST(TokenBucketTest, BurstGoesAtOnceThenTheRateHolds) {
  TokenBucket b(1e6, 100'000);                    // 1 MB/s, 100 kB burst
  EXPECT_EQ(b.take(100'000, 0), 0u);              // the burst
  EXPECT_EQ(b.take(50'000, 0), 50 * kMs);         // 50 kB at 1 MB/s: wait 50 ms
  EXPECT_EQ(b.take(50'000, 50 * kMs), 50 * kMs);  // the debt was paid at 50 ms; this one waits another 50
}

TEST(TokenBucketTest, LongRunRateIsTheConfiguredOne) {
  TokenBucket b(10e6, 1e6);  // 10 MB/s
  uint64_t now = 0, bytes = 0;
  for (int i = 0; i < 1000; ++i) {
    now += b.take(64 * 1024, now);  // a reader that sleeps as told
    bytes += 64 * 1024;
  }
  const double rate = static_cast<double>(bytes - 1'000'000) / (static_cast<double>(now) / 1e9);
  EXPECT_NEAR(rate, 10e6, 0.01 * 10e6);
}

TEST(TokenBucketTest, IdleTimeRefillsOnlyUpToTheBurst) {
  TokenBucket b(1e6, 10'000);
  EXPECT_EQ(b.take(10'000, 0), 0u);
  // An hour idle refills 10 kB, not 3.6 GB.
  EXPECT_EQ(b.take(10'000, 3600'000 * kMs), 0u);
  EXPECT_GT(b.take(10'000, 3600'000 * kMs), 0u);
}

TEST(TokenBucketTest, AReadLargerThanTheBurstIsServedAfterAWait) {
  TokenBucket b(1e6, 1'000);
  EXPECT_EQ(b.take(1'000'001, 0), 999'001'000u);  // 999 001 bytes beyond the burst at 1 MB/s: 999.001 ms
}

}  // namespace
}  // namespace texstream::server
