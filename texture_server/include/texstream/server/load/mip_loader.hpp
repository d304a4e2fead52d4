#pragma once
// Fills one staging slot with one mip: from the RAM cache, or from storage reading exactly that mip
// (seed 000 §3.5: never a whole file to get one mip).
//
// Which file: texture_file_index.hpp (<id>.dds, else .tx / .tif / .exr with the same stem). How it is read:
// - DDS whose encoding matches the texture table (BC1 blocks for a bc1 texture, R8G8B8A8 for rgba8): one
//   pread of the mip's byte range; BC1 reaches the renderer as BC1 blocks, never decoded.
// - Any other DDS encoding for an rgba8 texture, and TIFF / OpenEXR: that one level decoded by OpenImageIO
//   into RGBA8 (oiio_mip_decoder.hpp). A bc1 texture is never encoded here: such a file is kCorrupt.
// The file's extent of the asked mip must equal the texture table's, else kCorrupt. Errors are logged with
// the path. Thread-safe (workers call load() concurrently; the dispatcher calls serve_cached()).
#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <span>

#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/records.hpp"
#include "texstream/protocol/segment_layout.hpp"
#include "texstream/server/cache/mip_cache.hpp"
#include "texstream/server/load/load_request.hpp"
#include "texstream/server/load/server_stats.hpp"
#include "texstream/server/load/texture_file_index.hpp"
#include "texstream/server/storage/open_file_cache.hpp"
#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

class MipLoader {
 public:
  // `block` gets the segment's load counters (ServerBlock); `stats` the server's detailed statistics.
  MipLoader(std::filesystem::path scene_dir, Storage& storage, MipCache& cache, ServerBlock& block, ServerStats& stats);

  // Reads the mip from storage into `slot` (and into the cache when it is admissible). `record` is the
  // texture's entry of the texture table, already validated; `slot` holds at least the mip's bytes.
  // `local_only`: when a read it needs would go to a remote or slow origin (StorageFile::local() is false),
  // nothing is read and the completion is kUnfilled (not logged, not counted as a failure): the server then
  // hands the load to its bounded remote-fetch workers, or answers kUnfilled so the renderer asks again.
  // `read_tail`: when the mip is a DDS mip served raw and at most kTailMipBytes, the mips next to it that are
  // that small too and not cached yet (the texture's coarse tail, which lies back to back at the end of the
  // file) are read in the same single read and inserted into the cache, marked prefetched: the renderer
  // asks coarsest first (seed 000 §3.5), so they are its next requests, and each would otherwise cost a read
  // and a trip through the pipeline. Read amplification counts a prefetched mip as delivered only when it
  // is first served (MipCache::copy_into), so a tail nobody asks for shows up there. Only one thread may
  // pass read_tail = true (the dispatcher): two tail reads of one texture at once would read it twice.
  // `wanted_levels` (bit l = level l, with read_tail only): levels of the texture the renderer has asked for
  // too and that wait in the queue. They join the same read whatever their size, as long as the range stays
  // contiguous and within kMaxTailReadBytes: one read for what is asked anyway, no read amplification.
  // `hold_read` (with read_tail, the dispatcher only): the mips of this read are not inserted into the cache
  // yet but held back (the loader's "held read"), so that the texture's queued levels can be answered from
  // them by serve_held() without a cache lookup each; release_held() inserts them all under one lock. Any
  // later load() with read_tail releases the previous held read first; the dispatcher releases it at the end
  // of every dispatch pass, so the cache never waits long for them.
  // `deferred_decode` (the dispatcher's inline loads): non-null means "never decode here": a mip that needs a
  // decode (TIFF, OpenEXR, a DDS encoding that is not the texture's) comes back kUnfilled with the flag set,
  // nothing read beyond the header, so the caller hands it to a worker. A decode may start a helper process
  // (~1 s) and must never hold up the hits queued behind it (issue 27: a slow first decode looked like a hang).
  CompletionRecord load(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot_index,
                        std::span<std::byte> slot, bool local_only = false, bool read_tail = false,
                        uint32_t wanted_levels = 0, bool hold_read = false, bool* deferred_decode = nullptr);

  // If the held read (see load()'s hold_read) brought `request`'s mip and it has not been served from there
  // yet: copies it into `slot` and returns its kOk record, counted as serve_cached() counts a first hit of a
  // prefetched mip. Otherwise a record with status 0 (the caller asks the cache). Dispatcher only.
  CompletionRecord serve_held(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot_index,
                              std::span<std::byte> slot);
  // True if the held read has `key`'s mip (served from there or not): it is as good as cached.
  bool holds(MipKey key) const {
    return !held_.empty() && key.texture() == held_texture_ && key.mip().value < 32 &&
           ((held_levels_ >> key.mip().value) & 1u) != 0;
  }
  // Inserts the held read's mips into the cache (one lock) and forgets them. Cheap when nothing is held.
  void release_held();
  bool holding() const { return !held_.empty(); }

  // fail_status()'s rate limit on kTimedOut warnings (loads on several threads): at most one per period.
  static constexpr std::chrono::seconds kTimedOutLogPeriod{5};
  // Logs how many kTimedOut warnings the rate limit left out (see fail_status) once kTimedOutLogPeriod has
  // passed since the last such warning, or at once with `now_or_never`: without it, an outage's last count was
  // printed only at the next timeout, so never if the storage came back. Cheap when nothing was left out (one
  // relaxed load); the dispatcher calls it about once a millisecond and at exit.
  void log_left_out_timeouts(bool now_or_never = false);

  // The largest mip read as part of a coarse tail: 16 KiB = a 64x64 RGBA8 or 128x128 BC1 mip. A whole tail
  // of such mips is at most 4/3 of it (~22 KiB), which is what a texture wanted only at a coarser level
  // reads in vain (texstream-bench server's trace: read amplification stays near 1, see the bench note).
  static constexpr uint64_t kTailMipBytes = 16 << 10;
  // At most this many bytes in one tail read (the dispatcher makes it while hits wait behind it): 256 KiB
  // from the page cache is ~40 µs at the ~7 GB/s of plain read() here.
  static constexpr uint64_t kMaxTailReadBytes = 256 << 10;
  // At most this many mips in one tail read (a mip chain of up to 2^31 x 2^31 texels has 32).
  static constexpr size_t kMaxTailParts = 32;
  // The header read along with a texture's first tail read when its layout is guessed (read_mip): the
  // legacy DDS header texstream-gen writes (scene::kDdsHeaderBytes).
  static constexpr uint64_t kDdsGuessHeaderBytes = scene::kDdsHeaderBytes;
  // Copies a cached mip into `slot`. Returns a kOk record, or a record with status 0 on a cache miss.
  // True if the texture's file is known to be a DDS whose mips are served as they are stored (one pread per
  // mip, no decode) for a texture of `format`. False for unknown textures and for decoded ones.
  bool serves_raw(TextureId texture, TexelFormat format) const;
  // `prefetch_next`: MipCache::copy_into()'s hint. Called by one thread only (the dispatcher): the hit
  // counters it bumps have that one writer (no locked read-modify-write per hit).
  CompletionRecord serve_cached(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot_index,
                                std::span<std::byte> slot, std::optional<MipKey> prefetch_next = std::nullopt);

 private:
  struct Opened {
    std::string path;  // as text (Storage::open_text)
    TextureFileEntry entry;
    std::unique_ptr<StorageFile> file;
    // The first suffix, opened lazily (Storage::open_lazy) before the texture's file was known: a read that
    // finds no such file sets probe_missed instead of failing, and load() probes the other suffixes.
    bool lazy_probe = false;
    bool probe_missed = false;
    bool may_decode = true;        // false: a mip that needs a decode is left to a worker (load()'s deferred_decode)
    bool deferred_decode = false;  // read_mip() left such a mip undecoded
  };
  // Finds and opens the texture's file (or takes it from files_); on failure returns the error completion in
  // `error`. `after_lazy_probe`: the first suffix was tried lazily and is not there.
  bool open_texture(const LoadRequest& request, Opened& opened, CompletionRecord& error, bool after_lazy_probe = false);
  // A failed read: with a lazy probe's "no such file", marks it (no warning, no count); otherwise fail_status.
  CompletionStatus read_failed(const LoadRequest& request, Opened& opened, const Error& error);
  // Reads (or decodes) the mip into `target`; returns kOk or the failure's status (already logged).
  // With `tail` (read_tail, see load()): may read the coarse tail around the mip too; its other mips come
  // back in `tail` (checksummed by the caller, who inserts them).
  struct TailMip {
    uint32_t level = 0;
    std::shared_ptr<CachedMip> mip;
  };
  // read_tail's result: the mips read along, and the texture's levels the cache held when read_tail looked
  // (bit l = level l; load() uses it to decide whether the file can be closed at once).
  struct Tail {
    std::vector<TailMip> mips;
    uint32_t cached_levels = 0;
  };
  // `guess_layout` (with `tail` only): a DDS file whose layout is not known yet is assumed to be laid out as
  // texstream-gen writes it for the texture table's entry (legacy 128-byte header, the table's format, extent
  // and mip count); when the tail read then starts at mip 0 its header is read in the same read and checked
  // against the guess (read_tail). Saves the separate header read on a texture's first load: ~1 syscall of
  // ~4 per texture (texstream-bench server, misses, perf: the header pread was ~5 % of the dispatcher).
  CompletionStatus read_mip(const LoadRequest& request, const scene::TextureRecord& record, Opened& opened,
                            std::span<std::byte> target, bool local_only, Tail* tail = nullptr,
                            uint32_t wanted_levels = 0, bool guess_layout = true);
  // The coarse-tail read of read_mip(): levels around `request.mip` in one scatter read (see load()).
  // `guessed`: opened.entry.dds is read_mip()'s guess, not read from the file. Then the read must start at
  // mip 0 and takes the header along; the header is parsed and must equal the guess, which is then
  // remembered. Otherwise nothing is kept, `retry` is set and the caller reads the header the ordinary way
  // (the bytes already read stay counted: read amplification sees a wrong guess).
  CompletionStatus read_tail(const LoadRequest& request, const scene::TextureRecord& record, Opened& opened,
                             std::span<std::byte> target, bool local_only, Tail& tail, uint32_t wanted_levels,
                             bool guessed, bool& retry);
  // The statistics of a mip served from memory (serve_cached, serve_held): a RAM cache hit, and its bytes as
  // loaded if it is the first use of a mip read ahead.
  void count_served_cached(uint64_t bytes, bool first_use_of_prefetch);
  // After a tail read of `request`'s texture: true if every level of the texture (record.mip_count) is now
  // cached, held or in `tail` (the levels cached before are tail.cached_levels).
  static bool every_level_cached_after(const LoadRequest& request, const scene::TextureRecord& record,
                                       const Tail& tail);
  CompletionRecord fail(const LoadRequest& request, CompletionStatus status, const std::filesystem::path& path,
                        const std::string& why);
  CompletionStatus fail_status(const LoadRequest& request, CompletionStatus status, const std::filesystem::path& path,
                               const std::string& why);
  void count_read(uint64_t bytes);
  void log_left_out(uint64_t count);
  struct TimedOutLog {
    std::mutex mutex;
    std::chrono::steady_clock::time_point last{};
    // Changed under the lock; log_left_out_timeouts() reads it without, to skip the lock when it is 0.
    std::atomic<uint64_t> suppressed{0};
  };
  TimedOutLog timed_out_log_;

  std::filesystem::path scene_dir_;
  Storage& storage_;
  MipCache& cache_;
  ServerBlock& block_;
  ServerStats& stats_;
  TextureFileIndex index_;
  OpenFileCache files_;  // files of recent misses, kept open for the texture's next mips
  Tail tail_scratch_;    // read_tail's mips (used by the one thread that passes read_tail = true)
  // The held read (load()'s hold_read): its mips in the order read, each with how it has been used so far.
  // Only the dispatcher touches these. held_levels_: bit l = level l of held_texture_ is in held_.
  std::vector<LoadedMip> held_;
  TextureId held_texture_{0};
  uint32_t held_levels_ = 0;
};

// The completion a request gets when it is answered without a payload (a page's echoes its file, level, x, y).
CompletionRecord make_completion(const LoadRequest& request, CompletionStatus status);
// The status of a failed storage read (mip_loader.cpp says why each).
CompletionStatus read_failure_status(ErrorCode code);

}  // namespace texstream::server
