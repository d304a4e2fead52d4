#include "texstream/server/load/server_stats.hpp"

#include <algorithm>

#include <fmt/format.h>

#include "texstream/server/decode/decode_helper_pool.hpp"

namespace texstream::server {

namespace {
uint64_t get(const std::atomic<uint64_t>& v) { return v.load(std::memory_order_relaxed); }
}  // namespace

double read_amplification(const ServerStats& s) {
  const uint64_t loaded = get(s.bytes_loaded);
  return loaded == 0 ? 0.0 : static_cast<double>(get(s.bytes_read)) / static_cast<double>(loaded);
}

std::string format_stats(const ServerStats& s, const MipCacheStats& c) {
  const uint64_t lookups = c.hits + c.misses;
  const double hit_rate = lookups == 0 ? 0.0 : static_cast<double>(c.hits) / static_cast<double>(lookups);
  std::string out;
  out += fmt::format(
      "RAM cache: {} hits, {} misses (hit rate {:.3f}), {} insertions, {} evictions, {} rejections; "
      "{} entries, {} of {} bytes\n",
      c.hits, c.misses, hit_rate, c.insertions, c.evictions, c.rejections, c.entries, c.bytes, c.budget_bytes);
  // Mips read ahead count as loaded at their first use only: those not used (yet, or before their eviction)
  // are what the read amplification has on top of the exact reads. A short run (the 90-frame demo) and a
  // small cache have many of them.
  const uint64_t unused_mips = c.prefetched - std::min(c.prefetched, c.prefetch_hits);
  const uint64_t unused_bytes = c.prefetched_bytes - std::min(c.prefetched_bytes, c.prefetch_hit_bytes);
  out += fmt::format(
      "coarse tails: {} mips read ahead ({} bytes), {} of the hits were their first use; {} mips "
      "({} bytes) not used (yet, or before their eviction)\n",
      c.prefetched, c.prefetched_bytes, c.prefetch_hits, unused_mips, unused_bytes);
  const uint64_t loaded = get(s.bytes_loaded);
  const uint64_t read = get(s.bytes_read);
  const double asked_amplification =
      loaded == 0 ? 0.0 : static_cast<double>(read - std::min(read, unused_bytes)) / static_cast<double>(loaded);
  out += fmt::format(
      "storage: {} bytes read, {} bytes of mips loaded, read amplification {:.4f} ({:.4f} without the "
      "read-ahead not used); {} bytes served from the cache; rate-limit waits {} us\n",
      read, loaded, read_amplification(s), asked_amplification, get(s.bytes_served_cached), get(s.rate_limit_wait_us));
  out += fmt::format("completions: {} hits ok, {} loads ok, {} not found, {} corrupt, {} I/O errors, {} cancelled\n",
                     get(s.hits_ok), get(s.loads_ok), get(s.not_found), get(s.corrupt), get(s.io_errors),
                     get(s.cancelled));
  out += fmt::format("pages: {} ok, {} bytes read\n", get(s.pages_ok), get(s.page_bytes_read));
  out += fmt::format("queues (now/max): pending {}/{}, loads in flight {}/{}, completions waiting {}/{}\n",
                     get(s.pending.now), get(s.pending.max), get(s.in_flight.now), get(s.in_flight.max),
                     get(s.overflow.now), get(s.overflow.max));
  const uint64_t served = get(s.hits_ok) + get(s.loads_ok);
  out += fmt::format("system calls (dispatcher and workers): {}; {:.3f} per served mip\n", s.syscalls.describe(),
                     served == 0 ? 0.0 : static_cast<double>(s.syscalls.total()) / static_cast<double>(served));
  for (const auto& [name, h] :
       {std::pair<const char*, const LatencyHistogram*>{"hit", &s.hit_latency}, {"miss", &s.miss_latency}}) {
    out += fmt::format(
        "latency {:4} (request→completion, us): n={} mean={:.1f} p50={:.0f} p90={:.0f} p99={:.0f} "
        "max={}\n",
        name, h->count(), h->mean(), h->percentile(50), h->percentile(90), h->percentile(99), h->max());
  }
  // The process's decode helpers (one pool for every server in it); no line while no decode ever ran.
  if (const std::optional<DecodeHelperPoolStats> d = default_decode_helper_pool_stats()) {
    out += fmt::format(
        "decode helpers: {} started, {} crashed or hung, {} files quarantined, {} decodes refused "
        "as quarantined\n",
        d->helpers_started, d->helper_failures, d->files_quarantined, d->quarantine_refusals);
  }
  if (!out.empty()) out.pop_back();
  return out;
}

}  // namespace texstream::server
