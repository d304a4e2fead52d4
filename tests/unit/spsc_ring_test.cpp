// The SPSC ring over ordinary memory (the same code runs over the shared segment): order, capacity, the
// hostile-peer checks, and a two-thread stress that would show lost or reordered records.
#include <gtest/gtest.h>

#include <memory>
#include <thread>
#include <vector>

#include "texstream/protocol/records.hpp"
#include "texstream/protocol/spsc_ring.hpp"

namespace texstream {
namespace {

struct RingMemory {
  explicit RingMemory(uint32_t cap) : records(cap) {}
  RingControl control{};
  std::vector<RequestRecord> records;
};

RequestRecord load(uint32_t id) {
  RequestRecord r{};
  r.kind = static_cast<uint32_t>(RequestKind::kLoad);
  r.texture_id = id;
  return r;
}

TEST(SpscRing, FifoOrderAndCapacity) {
  RingMemory m(8);
  SpscRingProducer<RequestRecord> p(&m.control, m.records.data(), 8);
  SpscRingConsumer<RequestRecord> c(&m.control, m.records.data(), 8);
  EXPECT_FALSE(c.try_pop().has_value());
  for (uint32_t i = 0; i < 8; ++i) EXPECT_TRUE(p.try_push(load(i)));
  EXPECT_FALSE(p.try_push(load(99))) << "a full ring must refuse";
  EXPECT_EQ(c.size(), 8u);
  for (uint32_t i = 0; i < 8; ++i) {
    auto r = c.try_pop();
    ASSERT_TRUE(r.has_value());
    EXPECT_EQ(r->texture_id, i);
  }
  EXPECT_FALSE(c.try_pop().has_value());
  EXPECT_EQ(p.free_space(), 8u);
}

TEST(SpscRing, PositionsKeepIncreasingAcrossWraps) {
  RingMemory m(4);
  SpscRingProducer<RequestRecord> p(&m.control, m.records.data(), 4);
  SpscRingConsumer<RequestRecord> c(&m.control, m.records.data(), 4);
  for (uint32_t i = 0; i < 1000; ++i) {
    ASSERT_TRUE(p.try_push(load(i)));
    auto r = c.try_pop();
    ASSERT_TRUE(r.has_value());
    ASSERT_EQ(r->texture_id, i);
  }
  EXPECT_EQ(m.control.write_pos.v.load(), 1000u);
  EXPECT_EQ(m.control.read_pos.v.load(), 1000u);
}

TEST(SpscRing, ConsumerRejectsImpossibleWritePosition) {
  RingMemory m(8);
  SpscRingConsumer<RequestRecord> c(&m.control, m.records.data(), 8);
  // A hostile producer claims 100 records in an 8-record ring.
  m.control.write_pos.v.store(100);
  EXPECT_FALSE(c.try_pop().has_value());
  EXPECT_EQ(c.error(), RingError::kPeerCorrupt);
  EXPECT_EQ(c.size(), 0u);
  // Our own position never moved.
  EXPECT_EQ(c.position(), 0u);
}

TEST(SpscRing, ConsumerRejectsWritePositionGoingBackwards) {
  RingMemory m(8);
  SpscRingProducer<RequestRecord> p(&m.control, m.records.data(), 8);
  SpscRingConsumer<RequestRecord> c(&m.control, m.records.data(), 8);
  ASSERT_TRUE(p.try_push(load(1)));
  ASSERT_TRUE(c.try_pop().has_value());
  m.control.write_pos.v.store(0);  // rewound by a broken peer
  EXPECT_FALSE(c.try_pop().has_value());
  EXPECT_EQ(c.error(), RingError::kPeerCorrupt);
}

TEST(SpscRing, ProducerRejectsImpossibleReadPosition) {
  RingMemory m(8);
  SpscRingProducer<RequestRecord> p(&m.control, m.records.data(), 8);
  ASSERT_TRUE(p.try_push(load(1)));
  m.control.read_pos.v.store(5);  // consumer claims to have read records never written
  EXPECT_FALSE(p.try_push(load(2)));
  EXPECT_EQ(p.error(), RingError::kPeerCorrupt);
  // Our own write position is untouched: the shared word is published, never trusted.
  EXPECT_EQ(p.position(), 1u);
}

TEST(SpscRing, TwoThreadStressDeliversEveryRecordInOrder) {
  constexpr uint32_t kCap = 64;
  constexpr uint32_t kCount = 2'000'000;
  RingMemory m(kCap);
  SpscRingProducer<RequestRecord> p(&m.control, m.records.data(), kCap);
  SpscRingConsumer<RequestRecord> c(&m.control, m.records.data(), kCap);
  std::thread producer([&] {
    for (uint32_t i = 0; i < kCount;) {
      RequestRecord r = load(i);
      r.generation = uint64_t{i} * 3 + 1;  // a second field: a torn record would show a mismatch
      if (p.try_push(r))
        ++i;
      else
        std::this_thread::yield();
    }
  });
  uint32_t expected = 0;
  uint32_t mismatches = 0;
  while (expected < kCount) {
    if (auto r = c.try_pop()) {
      if (r->texture_id != expected || r->generation != uint64_t{expected} * 3 + 1) ++mismatches;
      ++expected;
    } else {
      std::this_thread::yield();
    }
  }
  producer.join();
  EXPECT_EQ(mismatches, 0u);
  EXPECT_EQ(c.error(), RingError::kNone);
  EXPECT_EQ(p.error(), RingError::kNone);
}

// ---- deferred publication (try_push_deferred / try_pop_deferred + publish) ----

TEST(SpscRingDeferred, PushedRecordsAreInvisibleUntilPublished) {
  RingMemory m(8);
  SpscRingProducer<RequestRecord> p(&m.control, m.records.data(), 8);
  SpscRingConsumer<RequestRecord> c(&m.control, m.records.data(), 8);
  for (uint32_t i = 0; i < 3; ++i) ASSERT_TRUE(p.try_push_deferred(load(i)));
  EXPECT_EQ(m.control.write_pos.v.load(), 0u) << "published before publish()";
  EXPECT_FALSE(c.try_pop().has_value());
  EXPECT_TRUE(p.has_deferred());
  p.publish();
  EXPECT_FALSE(p.has_deferred());
  EXPECT_EQ(m.control.write_pos.v.load(), 3u);
  for (uint32_t i = 0; i < 3; ++i) {
    auto r = c.try_pop();
    ASSERT_TRUE(r.has_value());
    EXPECT_EQ(r->texture_id, i);
  }
  // A plain try_push() after deferred ones publishes them all, in order.
  ASSERT_TRUE(p.try_push_deferred(load(10)));
  ASSERT_TRUE(p.try_push(load(11)));
  EXPECT_EQ(c.try_pop()->texture_id, 10u);
  EXPECT_EQ(c.try_pop()->texture_id, 11u);
}

TEST(SpscRingDeferred, AFullRingRefusesAndFreedPlacesAreSeenAfterTheConsumerPublishes) {
  RingMemory m(4);
  SpscRingProducer<RequestRecord> p(&m.control, m.records.data(), 4);
  SpscRingConsumer<RequestRecord> c(&m.control, m.records.data(), 4);
  for (uint32_t i = 0; i < 4; ++i) ASSERT_TRUE(p.try_push_deferred(load(i)));
  EXPECT_FALSE(p.try_push_deferred(load(99))) << "a full ring must refuse";
  p.publish();
  // The consumer takes two without handing their places back: still full for the producer.
  ASSERT_EQ(c.try_pop_deferred()->texture_id, 0u);
  ASSERT_EQ(c.try_pop_deferred()->texture_id, 1u);
  EXPECT_EQ(m.control.read_pos.v.load(), 0u) << "read position published before publish()";
  EXPECT_FALSE(p.try_push_deferred(load(4)));
  c.publish();
  EXPECT_EQ(m.control.read_pos.v.load(), 2u);
  EXPECT_TRUE(p.try_push_deferred(load(4)));
  EXPECT_TRUE(p.try_push_deferred(load(5)));
  EXPECT_FALSE(p.try_push_deferred(load(6)));
  p.publish();
  for (uint32_t want = 2; want < 6; ++want) {
    auto r = c.try_pop_deferred();
    ASSERT_TRUE(r.has_value()) << want;
    EXPECT_EQ(r->texture_id, want);
  }
  EXPECT_FALSE(c.try_pop_deferred().has_value());
  c.publish();
  EXPECT_EQ(p.free_space(), 4u);
}

TEST(SpscRingDeferred, ImpossiblePeerPositionsAreRejected) {
  {
    RingMemory m(8);
    SpscRingProducer<RequestRecord> p(&m.control, m.records.data(), 8);
    for (uint32_t i = 0; i < 8; ++i) ASSERT_TRUE(p.try_push_deferred(load(i)));
    p.publish();
    m.control.read_pos.v.store(100);  // claims records never written; seen when the ring looks full
    EXPECT_FALSE(p.try_push_deferred(load(8)));
    EXPECT_EQ(p.error(), RingError::kPeerCorrupt);
    EXPECT_EQ(p.position(), 8u);
  }
  {
    RingMemory m(8);
    SpscRingConsumer<RequestRecord> c(&m.control, m.records.data(), 8);
    m.control.write_pos.v.store(100);
    EXPECT_FALSE(c.try_pop_deferred().has_value());
    EXPECT_EQ(c.error(), RingError::kPeerCorrupt);
    EXPECT_EQ(c.position(), 0u);
  }
}

TEST(SpscRingDeferred, TwoThreadStressInBurstsDeliversEveryRecordInOrder) {
  constexpr uint32_t kCap = 64;
  constexpr uint32_t kCount = 1'000'000;
  RingMemory m(kCap);
  SpscRingProducer<RequestRecord> p(&m.control, m.records.data(), kCap);
  SpscRingConsumer<RequestRecord> c(&m.control, m.records.data(), kCap);
  std::thread producer([&] {
    uint32_t i = 0;
    while (i < kCount) {
      // Bursts of up to 8, then one publish (the server's pattern).
      uint32_t burst = 0;
      while (burst < 8 && i < kCount) {
        RequestRecord r = load(i);
        r.generation = uint64_t{i} * 3 + 1;
        if (!p.try_push_deferred(r)) break;
        ++i;
        ++burst;
      }
      p.publish();
      if (burst == 0) std::this_thread::yield();
    }
  });
  uint32_t expected = 0, mismatches = 0;
  while (expected < kCount) {
    uint32_t taken = 0;
    while (auto r = c.try_pop_deferred()) {
      if (r->texture_id != expected || r->generation != uint64_t{expected} * 3 + 1) ++mismatches;
      ++expected;
      if (++taken == 16) break;
    }
    c.publish();
    if (taken == 0) std::this_thread::yield();
  }
  producer.join();
  EXPECT_EQ(mismatches, 0u);
  EXPECT_EQ(c.error(), RingError::kNone);
  EXPECT_EQ(p.error(), RingError::kNone);
}

}  // namespace
}  // namespace texstream
