#include "texstream/server/load/mip_loader.hpp"
#include "texstream/server/support/fault_point.hpp"

#include <spdlog/spdlog.h>

#include <array>
#include <cstring>

#include "texstream/protocol/checksum.hpp"
#include "texstream/server/decode/oiio_mip_decoder.hpp"

namespace texstream::server {

CompletionRecord make_completion(const LoadRequest& request, CompletionStatus status) {
  CompletionRecord c{};
  c.status = static_cast<uint32_t>(status);
  c.slot = kNoSlot;
  c.texture_id = request.texture.value;
  c.mip_level = request.mip.value;
  c.generation = request.generation.value;
  c.request_kind = static_cast<uint32_t>(request.page ? RequestKind::kLoadPage : RequestKind::kLoad);
  c.page_x = request.page ? request.x : 0;
  c.page_y = request.page ? request.y : 0;
  return c;
}

// A failed storage read: a missing object (http 404) is kNotFound; an origin that did not answer in time,
// or does not answer at all now (refused or reset connections, 502/503/504: kUnavailable), kTimedOut, which
// the renderer asks again for without counting it against the texture (texture_states.cpp): before, an
// origin down for 2.5 s left 4 textures broken for the rest of the run after 4 refused connections each.
// Anything else — other 5xx, a wrong Content-Range, truncated bodies — kIoError, which the renderer retries a
// bounded number of times. kCorrupt only for a path that names no regular file (a FIFO or a directory in its
// place, kNotAFile): asking again cannot help, and it was 4 failed asks per texture as kIoError.
CompletionStatus read_failure_status(ErrorCode code) {
  switch (code) {
    case ErrorCode::kNotFound:
      return CompletionStatus::kNotFound;
    case ErrorCode::kTimeout:
    case ErrorCode::kUnavailable:
      return CompletionStatus::kTimedOut;
    case ErrorCode::kNotAFile:
      return CompletionStatus::kCorrupt;
    default:
      return CompletionStatus::kIoError;
  }
}

namespace {

CompletionRecord ok_completion(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot,
                               uint64_t bytes, uint64_t checksum) {
  CompletionRecord c = make_completion(request, CompletionStatus::kOk);
  const Extent2D e = mip_extent(record.width, record.height, request.mip.value);
  c.slot = slot;
  c.byte_size = bytes;
  c.format = record.format;
  c.width = e.width;
  c.height = e.height;
  c.checksum = checksum;
  return c;
}

CompletionStatus status_of(ErrorCode code) {
  switch (code) {
    case ErrorCode::kNotFound:
      return CompletionStatus::kNotFound;
    case ErrorCode::kCorrupt:
    case ErrorCode::kNotAFile:
    case ErrorCode::kUnsupported:
      return CompletionStatus::kCorrupt;
    case ErrorCode::kTimeout:
    case ErrorCode::kUnavailable:
      return CompletionStatus::kTimedOut;
    default:
      return CompletionStatus::kIoError;
  }
}

std::string extent_text(Extent2D e) { return std::to_string(e.width) + "x" + std::to_string(e.height); }

// The layout texstream-gen writes for a texture table entry (scene_format.hpp: legacy header, mips finest
// first, no DX10 extension): read_mip()'s guess before a texture's header has been read.
scene::DdsLayout generated_dds_layout(const scene::TextureRecord& record) {
  scene::DdsLayout l;
  const auto format = static_cast<TexelFormat>(record.format);
  l.encoding = format == TexelFormat::kBc1   ? scene::DdsEncoding::kBc1
               : format == TexelFormat::kBc3 ? scene::DdsEncoding::kBc3
               : format == TexelFormat::kBc7 ? scene::DdsEncoding::kBc7
                                             : scene::DdsEncoding::kRgba8;
  l.width = record.width;
  l.height = record.height;
  l.mip_count = record.mip_count;
  l.data_offset = MipLoader::kDdsGuessHeaderBytes;
  return l;
}

}  // namespace

MipLoader::MipLoader(std::filesystem::path scene_dir, Storage& storage, MipCache& cache, ServerBlock& block,
                     ServerStats& stats)
    : scene_dir_(std::move(scene_dir)), storage_(storage), cache_(cache), block_(block), stats_(stats) {}

CompletionStatus MipLoader::fail_status(const LoadRequest& request, CompletionStatus status,
                                        const std::filesystem::path& path, const std::string& why) {
  // A storage that does not answer fails every request the renderer asks again each cycle: one warning per
  // kTimedOutLogPeriod, with how many were left out since the last one (an nginx origin down for 2.5 s under
  // a paced renderer gave 54 lines).
  bool log = true;
  uint64_t quiet = 0;
  if (status == CompletionStatus::kTimedOut) {
    std::lock_guard lock(timed_out_log_.mutex);
    const auto now = std::chrono::steady_clock::now();
    if (now - timed_out_log_.last < kTimedOutLogPeriod) {
      timed_out_log_.suppressed.fetch_add(1, std::memory_order_relaxed);  // relaxed: the lock orders it
      log = false;
    } else {
      timed_out_log_.last = now;
      quiet = timed_out_log_.suppressed.exchange(0, std::memory_order_relaxed);
    }
  }
  if (log && quiet > 0) log_left_out(quiet);
  if (log) {
    spdlog::warn("texture {} mip {}: {} ({}): {}", request.texture.value, request.mip.value, to_string(status),
                 path.string(), why);
  }
  switch (status) {
    case CompletionStatus::kNotFound:
      stats_.add(stats_.not_found, 1);
      break;
    case CompletionStatus::kCorrupt:
      stats_.add(stats_.corrupt, 1);
      break;
    default:
      stats_.add(stats_.io_errors, 1);
      break;
  }
  return status;
}

void MipLoader::log_left_out(uint64_t count) {
  spdlog::warn(
      "{} more load(s) timed out or found the storage unavailable after the last such warning (at most one "
      "per {} s is logged)",
      count, std::chrono::duration_cast<std::chrono::seconds>(kTimedOutLogPeriod).count());
}

void MipLoader::log_left_out_timeouts(bool now_or_never) {
  if (timed_out_log_.suppressed.load(std::memory_order_relaxed) == 0) return;  // relaxed: rechecked under the lock
  uint64_t quiet = 0;
  {
    std::lock_guard lock(timed_out_log_.mutex);
    const auto now = std::chrono::steady_clock::now();
    if (!now_or_never && now - timed_out_log_.last < kTimedOutLogPeriod) return;
    quiet = timed_out_log_.suppressed.exchange(0, std::memory_order_relaxed);
    if (quiet == 0) return;
    timed_out_log_.last = now;  // this line counts as the period's warning
  }
  log_left_out(quiet);
}

CompletionRecord MipLoader::fail(const LoadRequest& request, CompletionStatus status, const std::filesystem::path& path,
                                 const std::string& why) {
  return make_completion(request, fail_status(request, status, path, why));
}

void MipLoader::count_read(uint64_t bytes) {
  block_.bytes_read.v.fetch_add(bytes, std::memory_order_relaxed);  // relaxed: statistic
  stats_.add(stats_.bytes_read, bytes);
}

CompletionRecord MipLoader::serve_cached(const LoadRequest& request, const scene::TextureRecord& record,
                                         uint32_t slot_index, std::span<std::byte> slot,
                                         std::optional<MipKey> prefetch_next) {
  // One lookup, copied under the cache's lock: no pin, no allocation.
  const std::optional<CachedCopy> hit = cache_.copy_into(request.key(), slot, prefetch_next);
  if (!hit) return CompletionRecord{};
  count_served_cached(hit->bytes, hit->first_use_of_prefetch);
  return ok_completion(request, record, slot_index, hit->bytes, hit->checksum);
}

void MipLoader::count_served_cached(uint64_t bytes, bool first_use_of_prefetch) {
  // relaxed: statistics, read for reports. Hits are served by one thread (the dispatcher, see the header):
  // load + store, no locked read-modify-write per hit.
  block_.ram_cache_hits.v.store(block_.ram_cache_hits.v.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  ServerStats::add_one_writer(stats_.bytes_served_cached, bytes);
  // A coarse-tail mip read ahead (load()'s read_tail) is delivered now: the read it came with counts it here.
  if (first_use_of_prefetch) stats_.add(stats_.bytes_loaded, bytes);
}

bool MipLoader::every_level_cached_after(const LoadRequest& request, const scene::TextureRecord& record,
                                         const Tail& tail) {
  if (record.mip_count > 32) return false;  // not tracked (cached_levels covers 32 levels)
  uint32_t have = tail.cached_levels | (1u << request.mip.value);
  for (const TailMip& t : tail.mips) have |= 1u << t.level;
  const uint32_t all = record.mip_count == 32 ? ~0u : (1u << record.mip_count) - 1;
  return (have & all) == all;
}

CompletionRecord MipLoader::serve_held(const LoadRequest& request, const scene::TextureRecord& record,
                                       uint32_t slot_index, std::span<std::byte> slot) {
  if (!holds(request.key())) return CompletionRecord{};
  for (LoadedMip& m : held_) {
    if (m.key != request.key()) continue;
    // Served from here once only (the asked mip by load() itself): a second request for it (a duplicate that
    // came after the first was answered) is an ordinary hit, so the held read goes into the cache first.
    if (m.use != LoadedUse::kReadAhead) {
      release_held();
      return CompletionRecord{};
    }
    const uint64_t bytes = m.mip->bytes.size();
    TS_ASSERT(bytes <= slot.size(), "held mip of %llu bytes does not fit a slot of %zu",
              static_cast<unsigned long long>(bytes), slot.size());
    copy_into_slot(slot.data(), m.mip->bytes.data(), bytes);  // kSlotWrite halfway
    m.use = LoadedUse::kServed;
    count_served_cached(bytes, /*first_use_of_prefetch=*/true);  // as serve_cached() counts it
    return ok_completion(request, record, slot_index, bytes, m.mip->checksum);
  }
  return CompletionRecord{};
}

void MipLoader::release_held() {
  if (held_.empty()) return;
  cache_.insert_loaded(held_);
  held_.clear();
  held_levels_ = 0;
}

bool MipLoader::serves_raw(TextureId texture, TexelFormat format) const {
  const std::optional<TextureFileEntry> e = index_.find(texture);
  if (!e || e->kind != TextureFileKind::kDds || !e->dds) return false;
  return e->dds->encoding != scene::DdsEncoding::kOther && e->dds->texel_format() == format;
}

bool MipLoader::open_texture(const LoadRequest& request, Opened& opened, CompletionRecord& error,
                             bool after_lazy_probe) {
  // A remembered file first: one open, no probing of the other suffixes.
  if (std::optional<TextureFileEntry> known = index_.find(request.texture)) {
    if (std::optional<OpenTextureFile> kept = files_.take(request.texture)) {
      opened.path = std::move(kept->path);
      opened.entry = *known;
      opened.file = std::move(kept->file);
      return true;
    }
    opened.path = texture_file_path_text(scene_dir_, request.texture, known->kind);
    Result<std::unique_ptr<StorageFile>> f = storage_.open_lazy(opened.path);
    if (f.ok()) {
      opened.entry = *known;
      opened.file = std::move(f).value();
      return true;
    }
    index_.forget(request.texture);  // gone or renamed since: probe again below
  }
  files_.take(request.texture);  // not remembered (forgotten after a failure): a kept file is stale, close it
  std::string tried = after_lazy_probe ? suffix_of(kTextureFileKinds[0]) : "";
  for (size_t k = after_lazy_probe ? 1 : 0; k < kTextureFileKinds.size(); ++k) {
    const TextureFileKind kind = kTextureFileKinds[k];
    std::string path = texture_file_path_text(scene_dir_, request.texture, kind);
    // The first suffix (what nearly every scene has) lazily: its first read opens it, in one io_uring
    // submission with the read and the close (issue 29); a miss there probes the rest the ordinary way.
    Result<std::unique_ptr<StorageFile>> f = k == 0 ? storage_.open_lazy(path) : storage_.open_text(path);
    if (f.ok()) {
      opened.path = std::move(path);
      opened.entry = TextureFileEntry{kind, std::nullopt};
      opened.file = std::move(f).value();
      opened.lazy_probe = opened.file->lazy();
      if (!opened.lazy_probe) index_.remember(request.texture, opened.entry);
      return true;
    }
    if (f.error().code != ErrorCode::kNotFound) {
      error = fail(request, CompletionStatus::kIoError, path, f.error().message);
      return false;
    }
    tried += tried.empty() ? suffix_of(kind) : std::string(", ") + suffix_of(kind);
  }
  error = fail(request, CompletionStatus::kNotFound, scene::texture_path(scene_dir_, request.texture),
               "no texture file (tried " + tried + ")");
  return false;
}

CompletionStatus MipLoader::read_failed(const LoadRequest& request, Opened& opened, const Error& error) {
  if (opened.lazy_probe && error.code == ErrorCode::kNotFound) {
    opened.probe_missed = true;
    return CompletionStatus::kNotFound;
  }
  return fail_status(request, read_failure_status(error.code), opened.path, error.message);
}

CompletionStatus MipLoader::read_tail(const LoadRequest& request, const scene::TextureRecord& record, Opened& opened,
                                      std::span<std::byte> target, bool local_only, Tail& tail, uint32_t wanted_levels,
                                      bool guessed, bool& retry) {
  retry = false;
  // read_mip() checked the asked level against the file (extent, encoding). A neighbour joins the read only
  // if it is small or wanted (asked for and queued), not cached, has the texture table's extent and exactly
  // the bytes the table implies, fits kMaxTailReadBytes and gets a cache payload; the first that does not
  // ends the range on that side (it must stay contiguous).
  const scene::DdsLayout& dds = *opened.entry.dds;
  const TexelFormat format = static_cast<TexelFormat>(record.format);
  const uint32_t level = request.mip.value;
  const uint32_t levels = std::min(dds.mip_count, record.mip_count);
  const uint32_t cached = cache_.cached_levels(request.texture, levels);  // one lock for all levels
  tail.cached_levels = cached;
  uint64_t total = target.size();
  const auto joins = [&](uint32_t l) -> std::shared_ptr<CachedMip> {
    const uint64_t bytes = mip_bytes(format, record.width, record.height, l);
    const bool wanted = l < 32 && ((wanted_levels >> l) & 1u) != 0;
    if ((bytes > kTailMipBytes && !wanted) || dds.mip_size(l) != bytes) return nullptr;
    if (total + bytes > kMaxTailReadBytes || tail.mips.size() + 1 >= kMaxTailParts) return nullptr;
    if (mip_extent(dds.width, dds.height, l) != mip_extent(record.width, record.height, l)) return nullptr;
    if (l < 32 && ((cached >> l) & 1u) != 0) return nullptr;
    std::shared_ptr<CachedMip> payload = cache_.make_payload(bytes);  // null: no room, or not admissible
    if (payload) total += bytes;
    return payload;
  };
  tail.mips.clear();
  uint32_t finest = level;
  for (uint32_t l = level + 1; l < levels; ++l) {  // coarser: after the asked mip in the file
    std::shared_ptr<CachedMip> m = joins(l);
    if (!m) break;
    tail.mips.push_back(TailMip{l, std::move(m)});
  }
  const size_t coarser = tail.mips.size();
  for (uint32_t l = level; l-- > 0;) {  // finer: before it in the file
    std::shared_ptr<CachedMip> m = joins(l);
    if (!m) break;
    tail.mips.push_back(TailMip{l, std::move(m)});
    finest = l;
  }
  // A guessed layout: the header is read along only if it lies right before the range (the range starts at
  // mip 0); otherwise the caller reads it first, the ordinary way, and nothing was read here.
  if (guessed && (finest != 0 || dds.data_offset != kDdsGuessHeaderBytes)) {
    tail.mips.clear();
    retry = true;
    return CompletionStatus::kOk;
  }
  // Parts in file order: (the header,) finest first.
  std::array<std::byte, kDdsGuessHeaderBytes> header{};
  std::array<std::span<std::byte>, kMaxTailParts + 1> parts{};
  size_t count = 0;
  if (guessed) {
    parts[count++] = header;
    total += header.size();
  }
  for (size_t i = tail.mips.size(); i-- > coarser;) parts[count++] = tail.mips[i].mip->bytes;
  parts[count++] = target;
  for (size_t i = 0; i < coarser; ++i) parts[count++] = tail.mips[i].mip->bytes;
  const uint64_t offset = guessed ? 0 : dds.mip_offset(finest);
  if (local_only && !opened.file->local(offset, total)) {
    tail.mips.clear();
    // A guess is only for ranges already here: otherwise the ordinary way decides, as it did before there
    // was a guess (a cached header is read now and remembered, so the remote fetch that follows does not
    // read it again; storage_origin_test's restart compares those byte counts).
    if (guessed) retry = true;
    return CompletionStatus::kUnfilled;
  }
  Result<uint64_t> got = opened.file->read_scatter_at(std::span(parts).first(count), offset);
  if (!got.ok()) {
    tail.mips.clear();
    return read_failed(request, opened, got.error());
  }
  count_read(*got);
  if (guessed) {
    // The guess holds only if the file's own header says exactly that; a short file, another header or any
    // other difference: start over the ordinary way (header first), which reports what is wrong, if anything.
    const Result<scene::DdsLayout> real =
        scene::parse_dds_layout(std::span(header).first(std::min<uint64_t>(*got, header.size())), opened.path);
    if (*got != total || !real.ok() || *real != dds) {
      tail.mips.clear();
      retry = true;
      return CompletionStatus::kOk;
    }
    index_.remember(request.texture, opened.entry);
    return CompletionStatus::kOk;
  }
  if (*got != total) {
    tail.mips.clear();
    index_.forget(request.texture);  // the file may have been replaced: look again next time
    return fail_status(request, CompletionStatus::kCorrupt, opened.path,
                       "truncated: mips " + std::to_string(finest) + ".." + std::to_string(finest + count - 1) +
                           " need bytes [" + std::to_string(offset) + ", " + std::to_string(offset + total) +
                           "), the file ends after " + std::to_string(offset + *got));
  }
  return CompletionStatus::kOk;
}

CompletionStatus MipLoader::read_mip(const LoadRequest& request, const scene::TextureRecord& record, Opened& opened,
                                     std::span<std::byte> target, bool local_only, Tail* tail, uint32_t wanted_levels,
                                     bool guess_layout) {
  const TexelFormat format = static_cast<TexelFormat>(record.format);  // validated with the texture table
  const uint32_t level = request.mip.value;
  const Extent2D expected = mip_extent(record.width, record.height, level);
  const std::string& path = opened.path;

  bool decode = opened.entry.kind != TextureFileKind::kDds;
  if (opened.entry.kind == TextureFileKind::kDds) {
    // See guess_layout (header). Checked below like a parsed layout; confirmed or dropped by read_tail.
    const bool guessed = !opened.entry.dds && tail != nullptr && guess_layout;
    if (guessed) opened.entry.dds = generated_dds_layout(record);
    if (!opened.entry.dds) {
      std::array<std::byte, scene::kDdsMaxHeaderBytes> header{};
      if (local_only && !opened.file->local(0, header.size())) return CompletionStatus::kUnfilled;
      Result<uint64_t> got = opened.file->read_at(header, 0);
      if (!got.ok()) return read_failed(request, opened, got.error());
      count_read(*got);
      Result<scene::DdsLayout> layout = scene::parse_dds_layout(std::span(header).first(*got), path);
      if (!layout.ok()) return fail_status(request, CompletionStatus::kCorrupt, path, layout.error().message);
      opened.entry.dds = *layout;
      index_.remember(request.texture, opened.entry);
    }
    const scene::DdsLayout& dds = *opened.entry.dds;
    if (level >= dds.mip_count) {
      return fail_status(request, CompletionStatus::kCorrupt, path,
                         "the file has " + std::to_string(dds.mip_count) + " mips, mip " + std::to_string(level) +
                             " was asked (the texture table says " + std::to_string(record.mip_count) + ")");
    }
    const Extent2D in_file = mip_extent(dds.width, dds.height, level);
    if (in_file != expected) {
      return fail_status(request, CompletionStatus::kCorrupt, path,
                         "mip " + std::to_string(level) + " is " + extent_text(in_file) + " in the file (" +
                             extent_text({dds.width, dds.height}) + " at mip 0), the texture table says " +
                             extent_text(expected));
    }
    if (is_block_compressed(format) && (dds.encoding == scene::DdsEncoding::kOther || dds.texel_format() != format)) {
      return fail_status(request, CompletionStatus::kCorrupt, path,
                         "the texture table says " + std::string(to_string(format)) + " but the file is not " +
                             (format == TexelFormat::kBc1   ? "BC1/DXT1"
                              : format == TexelFormat::kBc3 ? "BC3/DXT5"
                                                            : "BC7") +
                             " (the server never encodes block-compressed texels)");
    }
    decode = format == TexelFormat::kRgba8 && dds.encoding != scene::DdsEncoding::kRgba8;
    if (!decode && tail != nullptr && (target.size() <= kTailMipBytes || wanted_levels != 0)) {
      bool retry = false;
      const CompletionStatus s =
          read_tail(request, record, opened, target, local_only, *tail, wanted_levels, guessed, retry);
      if (!retry) return s;
    }
    if (guessed) {  // not confirmed: the ordinary way, the header first
      opened.entry.dds.reset();
      return read_mip(request, record, opened, target, local_only, tail, wanted_levels, /*guess_layout=*/false);
    }
    if (!decode) {
      // Exactly the mip's byte range.
      const uint64_t offset = dds.mip_offset(level);
      if (local_only && !opened.file->local(offset, target.size())) return CompletionStatus::kUnfilled;
      Result<uint64_t> got = opened.file->read_at(target, offset);
      if (!got.ok()) return read_failed(request, opened, got.error());
      count_read(*got);
      if (*got != target.size()) {
        index_.forget(request.texture);  // the file may have been replaced: look again next time
        return fail_status(request, CompletionStatus::kCorrupt, path,
                           "truncated: mip " + std::to_string(level) + " needs bytes [" + std::to_string(offset) +
                               ", " + std::to_string(offset + target.size()) + "), the file ends after " +
                               std::to_string(offset + *got));
      }
      return CompletionStatus::kOk;
    }
  }
  if (format != TexelFormat::kRgba8) {
    return fail_status(request, CompletionStatus::kCorrupt, path,
                       "the texture table says " + std::string(to_string(format)) +
                           " but the file holds decoded texels (only rgba8 textures may come from " +
                           suffix_of(opened.entry.kind) + " files)");
  }
  // OpenImageIO reads ranges of its own choosing: a remote file is decoded on a remote-fetch worker only.
  if (local_only && opened.file->remote()) return CompletionStatus::kUnfilled;
  if (!opened.may_decode) {  // the dispatcher: a worker decodes it (load()'s deferred_decode)
    opened.deferred_decode = true;
    return CompletionStatus::kUnfilled;
  }
  DecodeOutcome outcome;
  const Status decoded = decode_mip_rgba8(*opened.file, path, level, expected, target, outcome);
  count_read(outcome.bytes_read);
  if (!decoded.ok()) return fail_status(request, status_of(decoded.error().code), path, decoded.error().message);
  return CompletionStatus::kOk;
}

CompletionRecord MipLoader::load(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot_index,
                                 std::span<std::byte> slot, bool local_only, bool read_tail, uint32_t wanted_levels,
                                 bool hold_read, bool* deferred_decode) {
  if (deferred_decode) *deferred_decode = false;
  // A held read goes into the cache before this load looks at what is cached (read_tail's cached_levels).
  if (read_tail) release_held();
  const TexelFormat format = static_cast<TexelFormat>(record.format);  // validated with the texture table
  const uint64_t bytes = mip_bytes(format, record.width, record.height, request.mip.value);
  TS_ASSERT(bytes <= slot.size(), "mip of %llu bytes does not fit a slot of %zu (the dispatcher checks this)",
            static_cast<unsigned long long>(bytes), slot.size());
  // A local-only attempt that finds the mip remote comes back as a remote fetch: count the miss once, there.
  if (!local_only) block_.ram_cache_misses.v.fetch_add(1, std::memory_order_relaxed);  // relaxed: statistic

  Opened opened;
  opened.may_decode = deferred_decode == nullptr;
  CompletionRecord error{};
  if (!open_texture(request, opened, error)) return error;

  // Into a private buffer when the cache may keep it (the slot is shared memory the renderer could scribble
  // on; the cache must hold what we read), otherwise straight into the slot.
  std::shared_ptr<CachedMip> keep;
  std::span<std::byte> target = slot.first(bytes);
  if (cache_.admissible(bytes)) {
    keep = cache_.make_payload(bytes);  // warm arena memory (may evict); nullptr: into the slot, not cached
    if (keep) target = keep->bytes;
  }
  // Only with a cache payload: the tail is read for the cache. tail_scratch_ is the dispatcher's (read_tail
  // is its alone, see the header): no allocation per load once warm; other threads never touch it.
  Tail* const tail = read_tail && keep ? &tail_scratch_ : nullptr;
  if (tail) {
    tail->mips.clear();
    tail->cached_levels = 0;
  }
  CompletionStatus status = read_mip(request, record, opened, target, local_only, tail, wanted_levels);
  if (opened.probe_missed) {
    // The first suffix, opened lazily, is not there: the others, the ordinary way, then the read again.
    opened = Opened{};
    opened.may_decode = deferred_decode == nullptr;
    if (!open_texture(request, opened, error, /*after_lazy_probe=*/true)) return error;
    if (tail) {
      tail->mips.clear();
      tail->cached_levels = 0;
    }
    status = read_mip(request, record, opened, target, local_only, tail, wanted_levels);
  }
  if (deferred_decode) *deferred_decode = opened.deferred_decode;
  if (status == CompletionStatus::kUnfilled) {  // nothing was read: the file is as good as before
    files_.give_back(request.texture, OpenTextureFile{std::move(opened.path), std::move(opened.file)});
    return make_completion(request, status);
  }
  if (local_only) block_.ram_cache_misses.v.fetch_add(1, std::memory_order_relaxed);  // relaxed: statistic
  // Only a file that served its mip stays open; after a failure it is closed (it may have been replaced).
  if (status != CompletionStatus::kOk) return make_completion(request, status);
  if (tail != nullptr && every_level_cached_after(request, record, *tail)) {
    // Every level of the texture is cached or held now: closed at once rather than kept for a next miss that
    // comes only if the cache drops a level again (then it is opened again). Most textures are read whole by
    // their first tail read; files_'s bookkeeping per kept file, and closing it when it is pushed out later,
    // were ~2 % of the dispatcher in texstream-bench server's misses (perf).
    opened.file.reset();
  } else {
    files_.give_back(request.texture, OpenTextureFile{std::move(opened.path), std::move(opened.file)});
  }

  // The checksum is of the bytes we meant to hand over (equal to the slot's unless the renderer wrote into a
  // slot it does not own, which the renderer's own check then catches).
  const uint64_t checksum = payload_checksum(target.data(), bytes);
  if (keep) {
    keep->checksum = checksum;
    copy_into_slot(slot.data(), keep->bytes.data(), bytes);  // kSlotWrite halfway
  }
  if (tail) {
    for (TailMip& t : tail->mips) t.mip->checksum = payload_checksum(t.mip->bytes.data(), t.mip->bytes.size());
  }
  if (keep && tail && hold_read) {
    // Held back (see hold_read): the asked mip and its tail go into the cache together in release_held().
    held_texture_ = request.texture;
    held_levels_ = request.mip.value < 32 ? 1u << request.mip.value : 0;
    held_.push_back(LoadedMip{request.key(), std::move(keep), LoadedUse::kAsked});
    for (TailMip& t : tail->mips) {
      if (t.level < 32) held_levels_ |= 1u << t.level;
      held_.push_back(LoadedMip{MipKey(request.texture, MipLevel(t.level)), std::move(t.mip), LoadedUse::kReadAhead});
    }
    tail->mips.clear();
  } else {
    if (keep) cache_.insert(request.key(), std::move(keep));
    if (tail && !tail->mips.empty()) {
      std::array<std::pair<MipKey, std::shared_ptr<const CachedMip>>, kMaxTailParts> batch;
      size_t n = 0;
      for (TailMip& t : tail->mips) batch[n++] = {MipKey(request.texture, MipLevel(t.level)), std::move(t.mip)};
      tail->mips.clear();
      cache_.insert_all(std::span(batch).first(n), /*prefetched=*/true);
    }
  }
  stats_.add(stats_.bytes_loaded, bytes);
  return ok_completion(request, record, slot_index, bytes, checksum);
}

}  // namespace texstream::server
