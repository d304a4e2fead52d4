// MipLoader's coarse-tail read (load(..., read_tail, wanted_levels)) over an in-memory storage: which mips
// join the one read, that each lands in the cache with its own checksum and marked prefetched, that read
// amplification counts a prefetched mip only once it is served, and that a truncated range caches nothing.
// Also PosixStorage's preadv-based read_scatter_at on a real file, and MipCache's prefetched accounting.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "texstream/common/dds.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/protocol/segment_layout.hpp"
#include "texstream/server/cache/lru_eviction_policy.hpp"
#include "texstream/server/cache/mip_cache.hpp"
#include "texstream/server/load/mip_loader.hpp"
#include "texstream/server/load/server_stats.hpp"
#include "texstream/server/storage/posix_storage.hpp"

namespace texstream::server {
namespace {

struct Counters {
  int opens = 0;
  int reads = 0;          // read_at calls
  int scatter_reads = 0;  // read_scatter_at calls
};

class MemoryFile final : public StorageFile {
 public:
  MemoryFile(const std::vector<std::byte>& bytes, Counters* counters) : bytes_(bytes), counters_(counters) {}
  Result<uint64_t> read_at(std::span<std::byte> out, uint64_t offset) override {
    ++counters_->reads;
    return copy(out, offset);
  }
  Result<uint64_t> read_scatter_at(std::span<const std::span<std::byte>> parts, uint64_t offset) override {
    ++counters_->scatter_reads;
    uint64_t done = 0;
    for (const std::span<std::byte> part : parts) {
      const uint64_t got = copy(part, offset + done);
      done += got;
      if (got < part.size()) break;
    }
    return done;
  }
  Result<uint64_t> size() override { return uint64_t{bytes_.size()}; }

 private:
  uint64_t copy(std::span<std::byte> out, uint64_t offset) const {
    if (offset >= bytes_.size()) return 0;
    const uint64_t n = std::min<uint64_t>(out.size(), bytes_.size() - offset);
    std::memcpy(out.data(), bytes_.data() + offset, n);
    return n;
  }
  const std::vector<std::byte>& bytes_;
  Counters* counters_;
};

class MemoryStorage final : public Storage {
 public:
  Result<std::unique_ptr<StorageFile>> open(const std::filesystem::path& path) override {
    auto it = files.find(path.string());
    if (it == files.end()) return make_error(ErrorCode::kNotFound, "no '" + path.string() + "'");
    ++counters.opens;
    return std::unique_ptr<StorageFile>(new MemoryFile(it->second, &counters));
  }
  std::map<std::string, std::vector<std::byte>> files;
  Counters counters;
};

const std::filesystem::path kScene = "/scene";

// An rgba8 DDS of the generator's layout whose every byte says which mip it belongs to (level * 16 + i % 16).
std::vector<std::byte> make_dds(uint32_t width, uint32_t height, uint32_t mips) {
  const auto header = scene::make_dds_header(TexelFormat::kRgba8, width, height, mips);
  std::vector<std::byte> out(header.begin(), header.end());
  for (uint32_t l = 0; l < mips; ++l) {
    const uint64_t n = mip_bytes(TexelFormat::kRgba8, width, height, l);
    for (uint64_t i = 0; i < n; ++i) out.push_back(static_cast<std::byte>(l * 16 + i % 16));
  }
  return out;
}

std::span<const std::byte> mip_of(const std::vector<std::byte>& file, const scene::TextureRecord& t, uint32_t l) {
  const uint64_t offset = scene::kDdsHeaderBytes + mip_chain_offset(TexelFormat::kRgba8, t.width, t.height, l);
  return std::span(file).subspan(offset, mip_bytes(TexelFormat::kRgba8, t.width, t.height, l));
}

class TailRead : public ::testing::Test {
 protected:
  void add_texture(uint32_t width, uint32_t height) {
    record_ =
        scene::TextureRecord{width, height, full_mip_count(width, height), static_cast<uint32_t>(TexelFormat::kRgba8)};
    file_ = make_dds(width, height, record_.mip_count);
    storage_.files[texture_file_path(kScene, TextureId(0), TextureFileKind::kDds).string()] = file_;
  }
  LoadRequest request(uint32_t mip) const { return LoadRequest{TextureId(0), MipLevel(mip), Generation(1), 1.0f, 0}; }
  CompletionRecord load(uint32_t mip, bool tail, uint32_t wanted = 0) {
    return loader_.load(request(mip), record_, 0, slot_, /*local_only=*/true, tail, wanted);
  }
  bool cached(uint32_t mip) { return cache_.contains(MipKey(TextureId(0), MipLevel(mip))); }
  // Checks that `c` delivered `mip` into the slot: its status, size, bytes and checksum against the file.
  void expect_delivered(const CompletionRecord& c, uint32_t mip) {
    ASSERT_EQ(c.status, static_cast<uint32_t>(CompletionStatus::kOk)) << "mip " << mip;
    const std::span<const std::byte> want = mip_of(file_, record_, mip);
    ASSERT_EQ(c.byte_size, want.size());
    EXPECT_EQ(std::memcmp(slot_.data(), want.data(), want.size()), 0) << "mip " << mip;
    EXPECT_EQ(c.checksum, payload_checksum(want.data(), want.size())) << "mip " << mip;
  }
  // Serves `mip` from the cache and checks it (expect_delivered).
  void expect_hit(uint32_t mip) { expect_delivered(loader_.serve_cached(request(mip), record_, 0, slot_), mip); }

  MemoryStorage storage_;
  MipCache cache_{1 << 20, std::make_unique<LruEvictionPolicy>()};
  ServerBlock block_{};
  ServerStats stats_;
  MipLoader loader_{kScene, storage_, cache_, block_, stats_};
  std::vector<std::byte> slot_ = std::vector<std::byte>(1 << 20);
  scene::TextureRecord record_{};
  std::vector<std::byte> file_;
};

TEST_F(TailRead, TheCoarsestMipBringsEverySmallMipInOneRead) {
  add_texture(64, 64);  // mips of 16 KiB (= kTailMipBytes), 4 KiB, ..., 4 bytes: 7 levels
  const CompletionRecord c = load(6, /*tail=*/true);
  ASSERT_EQ(c.status, static_cast<uint32_t>(CompletionStatus::kOk));
  const std::span<const std::byte> m6 = mip_of(file_, record_, 6);
  EXPECT_EQ(c.checksum, payload_checksum(m6.data(), m6.size()));
  EXPECT_EQ(storage_.counters.reads, 0);          // no header read of its own: the guessed layout held
  EXPECT_EQ(storage_.counters.scatter_reads, 1);  // the header and every mip at once
  for (uint32_t l = 0; l < 7; ++l) EXPECT_TRUE(cached(l)) << "mip " << l;
  EXPECT_EQ(cache_.stats().prefetched, 6u);
  // Read amplification so far: the whole chain read, one mip delivered.
  const uint64_t chain = mip_chain_offset(TexelFormat::kRgba8, 64, 64, 7);
  EXPECT_EQ(stats_.bytes_read.load(), scene::kDdsHeaderBytes + chain);  // the legacy header, read along
  EXPECT_EQ(stats_.bytes_loaded.load(), m6.size());
  // The report tells the read-ahead not used (yet) apart: without it, only the header is read in vain.
  EXPECT_EQ(cache_.stats().prefetched_bytes, chain - m6.size());
  EXPECT_EQ(cache_.stats().prefetch_hit_bytes, 0u);
  const std::string report = format_stats(stats_, cache_.stats());
  EXPECT_NE(report.find(fmt::format("6 mips ({} bytes) not used (yet, or before their eviction)", chain - m6.size())),
            std::string::npos)
      << report;
  EXPECT_NE(report.find(
                fmt::format("({:.4f} without the read-ahead not used)",
                            static_cast<double>(scene::kDdsHeaderBytes + m6.size()) / static_cast<double>(m6.size()))),
            std::string::npos)
      << report;
  for (uint32_t l = 6; l-- > 0;) expect_hit(l);
  // Each prefetched mip counted as delivered once, at its first hit; a second hit counts nothing.
  EXPECT_EQ(stats_.bytes_loaded.load(), chain);
  expect_hit(0);
  EXPECT_EQ(stats_.bytes_loaded.load(), chain);
  EXPECT_EQ(cache_.stats().prefetch_hits, 6u);
  EXPECT_EQ(cache_.stats().prefetch_hit_bytes, chain - m6.size());
  EXPECT_NE(format_stats(stats_, cache_.stats()).find("0 mips (0 bytes) not used"), std::string::npos);
  EXPECT_EQ(storage_.counters.scatter_reads + storage_.counters.reads, 1);  // nothing read again
}

TEST_F(TailRead, AHeldReadServesItsLevelsWithoutTheCacheThenInsertsThemTogether) {
  add_texture(64, 64);  // 7 levels, all in one read (see above)
  const CompletionRecord c =
      loader_.load(request(6), record_, 0, slot_, /*local_only=*/true, /*read_tail=*/true, 0, /*hold_read=*/true);
  ASSERT_EQ(c.status, static_cast<uint32_t>(CompletionStatus::kOk));
  const std::span<const std::byte> m6 = mip_of(file_, record_, 6);
  EXPECT_EQ(std::memcmp(slot_.data(), m6.data(), m6.size()), 0);
  EXPECT_EQ(c.checksum, payload_checksum(m6.data(), m6.size()));
  // Held back: nothing is in the cache yet, but the loader has every level.
  for (uint32_t l = 0; l < 7; ++l) {
    EXPECT_FALSE(cached(l)) << "mip " << l;
    EXPECT_TRUE(loader_.holds(MipKey(TextureId(0), MipLevel(l)))) << "mip " << l;
  }
  EXPECT_FALSE(loader_.holds(MipKey(TextureId(1), MipLevel(0))));
  EXPECT_EQ(cache_.stats().insertions, 0u);
  // Levels 5 and 3 are served from the held read: the file's bytes and checksums, counted as hits.
  for (const uint32_t l : {5u, 3u}) {
    std::fill(slot_.begin(), slot_.end(), std::byte{0xee});
    ASSERT_NO_FATAL_FAILURE(expect_delivered(loader_.serve_held(request(l), record_, 0, slot_), l));
  }
  EXPECT_EQ(block_.ram_cache_hits.v.load(), 2u);
  EXPECT_EQ(stats_.bytes_loaded.load(),
            m6.size() + mip_of(file_, record_, 5).size() + mip_of(file_, record_, 3).size());
  // A level served once (or the asked one) is not served from the held read again: the held read goes into
  // the cache and the caller asks the cache, which then has it.
  EXPECT_EQ(loader_.serve_held(request(6), record_, 0, slot_).status, 0u);
  EXPECT_FALSE(loader_.holds(MipKey(TextureId(0), MipLevel(0))));
  for (uint32_t l = 0; l < 7; ++l) EXPECT_TRUE(cached(l)) << "mip " << l;
  // Counted as if each had been inserted first and copied out then: 2 hits, both first uses of read-ahead
  // mips; the 4 levels not served yet are prefetched entries whose first hit counts their bytes.
  MipCacheStats st = cache_.stats();
  EXPECT_EQ(st.insertions, 7u);
  EXPECT_EQ(st.hits, 2u);
  EXPECT_EQ(st.prefetch_hits, 2u);
  EXPECT_EQ(st.prefetched, 6u);
  for (const uint32_t l : {4u, 2u, 1u, 0u}) expect_hit(l);
  expect_hit(5);  // a second use: counts no bytes as loaded
  EXPECT_EQ(stats_.bytes_loaded.load(), mip_chain_offset(TexelFormat::kRgba8, 64, 64, 7));
  st = cache_.stats();
  EXPECT_EQ(st.prefetch_hits, 6u);
  EXPECT_EQ(st.prefetched_bytes, mip_chain_offset(TexelFormat::kRgba8, 64, 64, 7) - m6.size());
  EXPECT_EQ(st.prefetch_hit_bytes, st.prefetched_bytes);  // the held read's served levels count as used
  EXPECT_EQ(st.hits, 7u);
  EXPECT_EQ(storage_.counters.scatter_reads + storage_.counters.reads, 1);  // one read for everything
}

TEST_F(TailRead, ANewHeldReadReleasesThePreviousOneFirst) {
  add_texture(64, 64);
  ASSERT_EQ(loader_.load(request(6), record_, 0, slot_, true, true, 0, /*hold_read=*/true).status,
            static_cast<uint32_t>(CompletionStatus::kOk));
  // The next tail load (here of the same texture's finest level, which the held read already has) first puts
  // the held mips into the cache, so it sees them cached and reads nothing again.
  ASSERT_EQ(loader_.load(request(0), record_, 0, slot_, true, true, 0, /*hold_read=*/true).status,
            static_cast<uint32_t>(CompletionStatus::kOk));
  EXPECT_EQ(cache_.stats().insertions, 7u);
  EXPECT_EQ(storage_.counters.scatter_reads + storage_.counters.reads, 2);
  EXPECT_EQ(stats_.bytes_read.load(), scene::kDdsHeaderBytes + mip_chain_offset(TexelFormat::kRgba8, 64, 64, 7) +
                                          mip_of(file_, record_, 0).size());
  loader_.release_held();
  loader_.release_held();                    // nothing held: a no-op
  EXPECT_EQ(cache_.stats().insertions, 7u);  // mip 0's second copy found its key cached (as a raced load)
}

TEST_F(TailRead, AFileIsKeptOpenOnlyWhileSomeOfItsLevelsAreNotRead) {
  add_texture(256, 256);  // 9 levels; mip 0 (256 KiB) joins a tail read only when wanted
  ASSERT_EQ(load(8, true).status, static_cast<uint32_t>(CompletionStatus::kOk));
  EXPECT_FALSE(cached(0));
  EXPECT_EQ(storage_.counters.opens, 1);
  // Mip 0 is still to come: the file was kept open, so its load opens nothing.
  ASSERT_EQ(load(0, true).status, static_cast<uint32_t>(CompletionStatus::kOk));
  EXPECT_EQ(storage_.counters.opens, 1);
}

TEST_F(TailRead, AFileReadWholeByOneTailReadIsClosedAtOnce) {
  add_texture(64, 64);  // 7 levels, all in one tail read
  ASSERT_EQ(load(6, true).status, static_cast<uint32_t>(CompletionStatus::kOk));
  for (uint32_t l = 0; l < 7; ++l) ASSERT_TRUE(cached(l)) << "mip " << l;
  EXPECT_EQ(storage_.counters.opens, 1);
  // Nothing was left to read, so the file was closed rather than kept: a later load (as after an eviction)
  // opens it again.
  ASSERT_EQ(load(0, false).status, static_cast<uint32_t>(CompletionStatus::kOk));
  EXPECT_EQ(storage_.counters.opens, 2);
  // Without a tail read nothing says what is cached: that file is kept, as before.
  ASSERT_EQ(load(1, false).status, static_cast<uint32_t>(CompletionStatus::kOk));
  EXPECT_EQ(storage_.counters.opens, 2);
}

TEST_F(TailRead, LargeMipsJoinOnlyWhenWanted) {
  add_texture(256, 256);  // mip 0: 256 KiB, mip 1: 64 KiB, mip 2: 16 KiB, ...
  // Mip 1 is asked for and queued: it joins; mip 0 is not asked for: it stays out although it is contiguous.
  ASSERT_EQ(load(8, true, /*wanted=*/1u << 1).status, static_cast<uint32_t>(CompletionStatus::kOk));
  for (uint32_t l = 1; l < 9; ++l) EXPECT_TRUE(cached(l)) << "mip " << l;
  EXPECT_FALSE(cached(0));
  // The range does not start at mip 0, so the header is not next to it: read on its own, before the range
  // (the guess read nothing).
  EXPECT_EQ(storage_.counters.reads, 1);
  EXPECT_EQ(storage_.counters.scatter_reads, 1);
  for (uint32_t l = 8; l-- > 1;) expect_hit(l);
}

// The same texture stored with the DX10 header extension (148 bytes): the generator's layout guessed for it
// does not hold, so the loader starts over with the header read on its own; the bytes delivered are exact
// and the wasted read is counted in bytes_read (read amplification shows it).
TEST_F(TailRead, AWrongLayoutGuessIsReadAgainTheOrdinaryWay) {
  add_texture(64, 64);
  std::vector<std::byte> dx10(file_.begin(), file_.begin() + scene::kDdsHeaderBytes);
  const auto put = [&](size_t offset, uint32_t v) { std::memcpy(dx10.data() + offset, &v, 4); };
  put(80, 0x4);          // pixel format flags: FourCC
  put(84, 0x30315844u);  // "DX10"
  dx10.resize(scene::kDdsMaxHeaderBytes);
  put(128, 28);  // DXGI_FORMAT_R8G8B8A8_UNORM
  put(132, 3);   // texture 2D
  put(136, 0);
  put(140, 1);  // array size
  put(144, 0);
  dx10.insert(dx10.end(), file_.begin() + scene::kDdsHeaderBytes, file_.end());
  storage_.files.begin()->second = dx10;
  const CompletionRecord c = load(6, /*tail=*/true);
  ASSERT_EQ(c.status, static_cast<uint32_t>(CompletionStatus::kOk));
  EXPECT_EQ(storage_.counters.scatter_reads, 2);  // the guess, then the real range
  EXPECT_EQ(storage_.counters.reads, 1);          // the header, on its own
  const uint64_t chain = mip_chain_offset(TexelFormat::kRgba8, 64, 64, 7);
  EXPECT_EQ(stats_.bytes_read.load(), (scene::kDdsHeaderBytes + chain) + scene::kDdsMaxHeaderBytes + chain);
  // Every mip's bytes are the file's own (mip_of() computes legacy offsets: the same bytes, 20 bytes later).
  for (uint32_t l = 6; l-- > 0;) expect_hit(l);
  // Known now: the next load of the texture neither guesses nor reads the header again.
  storage_.counters = Counters{};
  const uint64_t before = stats_.bytes_read.load();
  ASSERT_EQ(load(6, /*tail=*/false).status, static_cast<uint32_t>(CompletionStatus::kOk));
  EXPECT_EQ(storage_.counters.reads, 1);  // the mip alone
  EXPECT_EQ(stats_.bytes_read.load() - before, 4u);
}

// A file whose header contradicts the texture table (fewer mips than the table says): the guess is
// dropped and the ordinary path reports the file as corrupt, as it did before there was a guess.
TEST_F(TailRead, AGuessTheHeaderContradictsEndsAsTheOrdinaryPathEnds) {
  add_texture(64, 64);
  std::vector<std::byte>& f = storage_.files.begin()->second;
  const uint32_t fewer = 5;
  std::memcpy(f.data() + 28, &fewer, 4);  // dwMipMapCount
  const CompletionRecord c = load(6, /*tail=*/true);
  EXPECT_EQ(c.status, static_cast<uint32_t>(CompletionStatus::kCorrupt));
  EXPECT_EQ(cache_.stats().entries, 0u);
  EXPECT_EQ(storage_.counters.reads, 1);  // the header, read the ordinary way after the guess failed
}

TEST_F(TailRead, AWantedMipBeyondTheReadLimitStaysOut) {
  add_texture(256, 256);
  // Mip 0 wanted as well would make the read 256 KiB + the rest > kMaxTailReadBytes: it is left to its own read.
  ASSERT_EQ(load(8, true, (1u << 0) | (1u << 1)).status, static_cast<uint32_t>(CompletionStatus::kOk));
  EXPECT_FALSE(cached(0));
  EXPECT_TRUE(cached(1));
  EXPECT_EQ(storage_.counters.scatter_reads, 1);
}

TEST_F(TailRead, WithoutReadTailOnlyTheAskedMipIsRead) {
  add_texture(64, 64);
  ASSERT_EQ(load(6, /*tail=*/false).status, static_cast<uint32_t>(CompletionStatus::kOk));
  EXPECT_EQ(storage_.counters.scatter_reads, 0);
  EXPECT_EQ(cache_.stats().entries, 1u);
  EXPECT_EQ(stats_.bytes_loaded.load(), 4u);
}

TEST_F(TailRead, ACachedLevelEndsTheRange) {
  add_texture(64, 64);
  ASSERT_EQ(load(3, false).status, static_cast<uint32_t>(CompletionStatus::kOk));  // mip 3 cached first
  const uint64_t read_before = stats_.bytes_read.load();
  ASSERT_EQ(load(6, true).status, static_cast<uint32_t>(CompletionStatus::kOk));
  // Mips 6, 5, 4 are read (contiguous up to the cached mip 3); mips 2..0 lie beyond it and are not.
  EXPECT_EQ(stats_.bytes_read.load() - read_before, 4u + 16u + 64u);  // 1x1, 2x2, 4x4 texels
  EXPECT_TRUE(cached(4));
  EXPECT_FALSE(cached(2));
  EXPECT_EQ(cache_.stats().prefetched, 2u);
}

TEST_F(TailRead, ATruncatedRangeIsCorruptAndCachesNothing) {
  add_texture(64, 64);
  // Cut the file inside mip 0: the asked mip 6 and the rest of the tail lie beyond the end.
  storage_.files.begin()->second.resize(scene::kDdsHeaderBytes + 1000);
  file_ = storage_.files.begin()->second;
  const CompletionRecord c = load(6, true);
  EXPECT_EQ(c.status, static_cast<uint32_t>(CompletionStatus::kCorrupt));
  EXPECT_EQ(cache_.stats().entries, 0u);
  EXPECT_EQ(cache_.stats().prefetched, 0u);
}

TEST(MipCachePrefetched, FirstUseIsReportedOnce) {
  MipCache cache(1 << 20, std::make_unique<LruEvictionPolicy>());
  auto mip = std::make_shared<CachedMip>();
  mip->bytes.assign(100, std::byte{3});
  mip->checksum = 77;
  const MipKey key(TextureId(5), MipLevel(2));
  ASSERT_TRUE(cache.insert(key, mip, /*prefetched=*/true));
  std::vector<std::byte> dst(100);
  const std::optional<CachedCopy> first = cache.copy_into(key, dst);
  ASSERT_TRUE(first.has_value());
  EXPECT_TRUE(first->first_use_of_prefetch);
  EXPECT_EQ(first->checksum, 77u);
  EXPECT_FALSE(cache.copy_into(key, dst)->first_use_of_prefetch);
  EXPECT_EQ(cache.stats().prefetched, 1u);
  EXPECT_EQ(cache.stats().prefetch_hits, 1u);
  // An ordinary insert is never a prefetch; a hint for a key that is not cached changes nothing.
  const MipKey other(TextureId(6), MipLevel(0));
  ASSERT_TRUE(cache.insert(other, mip));
  EXPECT_FALSE(cache.copy_into(other, dst, MipKey(TextureId(9), MipLevel(9)))->first_use_of_prefetch);
  EXPECT_EQ(cache.stats().hits, 3u);
}

TEST(MipCacheBatch, InsertAllKeepsTheBudgetAndCachedLevelsSeesEveryLevel) {
  MipCache cache(1000, std::make_unique<LruEvictionPolicy>());
  std::vector<std::pair<MipKey, std::shared_ptr<const CachedMip>>> batch;
  for (uint32_t l = 0; l < 4; ++l) {
    auto m = std::make_shared<CachedMip>();
    m->bytes.assign(400, std::byte{1});
    batch.emplace_back(MipKey(TextureId(1), MipLevel(l)), m);
  }
  // 4 x 400 bytes into 1000: each insert evicts as needed, so the last two stay.
  EXPECT_EQ(cache.insert_all(batch, true), 4u);
  EXPECT_LE(cache.stats().bytes, 1000u);
  EXPECT_EQ(cache.cached_levels(TextureId(1), 4), (1u << 2) | (1u << 3));
  EXPECT_EQ(cache.cached_levels(TextureId(2), 4), 0u);
}

TEST(PosixScatterRead, FillsThePartsInOrderAndStopsAtTheEnd) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("texstream-scatter-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::filesystem::path path = dir / "f.bin";
  {
    std::ofstream f(path, std::ios::binary);
    for (int i = 0; i < 100; ++i) f.put(static_cast<char>(i));
  }
  PosixStorage storage;
  auto file = storage.open(path);
  ASSERT_TRUE(file.ok());
  std::vector<std::byte> a(10), b(1), c(30);
  const std::array<std::span<std::byte>, 3> parts{a, b, c};
  Result<uint64_t> got = (*file)->read_scatter_at(parts, 5);
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(*got, 41u);
  EXPECT_EQ(a[0], std::byte{5});
  EXPECT_EQ(b[0], std::byte{15});
  EXPECT_EQ(c[29], std::byte{45});
  // Past the end: fewer bytes, the rest of the parts untouched.
  std::vector<std::byte> d(8, std::byte{0xee}), e(8, std::byte{0xee});
  const std::array<std::span<std::byte>, 2> tail{d, e};
  got = (*file)->read_scatter_at(tail, 90);
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(*got, 10u);
  EXPECT_EQ(d[7], std::byte{97});
  EXPECT_EQ(e[1], std::byte{99});
  EXPECT_EQ(e[2], std::byte{0xee});
  std::filesystem::remove_all(dir);
}

// PosixStorage opens files relative to a kept descriptor of their directory.
TEST(PosixStorageDirectories, OpensThroughKeptDirectoriesAndForgetsNoneThatAreMissing) {
  const std::filesystem::path root =
      std::filesystem::temp_directory_path() / ("texstream-posix-dirs-" + std::to_string(::getpid()));
  std::filesystem::remove_all(root);
  std::filesystem::create_directories(root / "a");
  { std::ofstream(root / "a" / "one.bin", std::ios::binary) << "0123456789"; }
  PosixStorage storage;
  Result<std::unique_ptr<StorageFile>> f = storage.open(root / "a" / "one.bin");
  ASSERT_TRUE(f.ok()) << f.error().message;
  std::array<std::byte, 4> buf{};
  Result<uint64_t> got = (*f)->read_at(buf, 3);
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(*got, 4u);
  EXPECT_EQ(buf[0], std::byte{'3'});
  EXPECT_EQ(storage.directories_kept(), 1u);
  // A missing file in a kept directory, and a file in a directory that does not exist (yet): kNotFound
  // naming the whole path; the missing directory is not remembered.
  Result<std::unique_ptr<StorageFile>> missing = storage.open(root / "a" / "two.bin");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
  EXPECT_NE(missing.error().message.find((root / "a" / "two.bin").string()), std::string::npos);
  Result<std::unique_ptr<StorageFile>> no_dir = storage.open(root / "b" / "x.bin");
  ASSERT_FALSE(no_dir.ok());
  EXPECT_EQ(no_dir.error().code, ErrorCode::kNotFound);
  EXPECT_EQ(storage.directories_kept(), 1u);
  // The directory appears later: its files open.
  std::filesystem::create_directories(root / "b");
  { std::ofstream(root / "b" / "x.bin", std::ios::binary) << "x"; }
  EXPECT_TRUE(storage.open(root / "b" / "x.bin").ok());
  EXPECT_EQ(storage.directories_kept(), 2u);
  // A bare relative name has no directory to keep: opened as it is (and not found here).
  EXPECT_EQ(storage.open("texstream-no-such-file.bin").error().code, ErrorCode::kNotFound);
  // A kept directory replaced in place (a scene folder swapped): its new files still open, by the full path.
  std::filesystem::rename(root / "a", root / "a-old");
  std::filesystem::create_directories(root / "a");
  { std::ofstream(root / "a" / "new.bin", std::ios::binary) << "n"; }
  EXPECT_TRUE(storage.open(root / "a" / "new.bin").ok()) << "a replaced directory hid its new files";
  std::filesystem::remove_all(root);
}

}  // namespace
}  // namespace texstream::server
