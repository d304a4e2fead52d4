#pragma once
// The server's statistics (issue 3): hits, misses, evictions, bytes read, read amplification, queue lengths
// and request→completion latency histograms for hits and misses. Counters are relaxed atomics written by
// the dispatcher and the workers; a snapshot may be taken from any thread (the bench reads it while the
// server runs). Printed at exit and on SIGUSR1 (format_stats), with the process's decode helpers' counters
// (crashes, quarantined files: decode_helper_pool.hpp).
#include <atomic>
#include <cstdint>
#include <string>

#include "texstream/common/latency_histogram.hpp"
#include "texstream/common/syscall_count.hpp"
#include "texstream/server/cache/mip_cache.hpp"

namespace texstream::server {

// Request→completion latencies in microseconds: 4 buckets per power of two (≤ 19 % relative error) up to
// 2^30 µs, so a histogram is a fixed 1 KiB whatever the run length.
using LatencyHistogram = LogLinearHistogram<2, 30>;

struct QueueGauge {
  std::atomic<uint64_t> now{0};
  std::atomic<uint64_t> max{0};
  void set(uint64_t v) {  // one writer (the dispatcher): relaxed load + store, no read-modify-write needed
    now.store(v, std::memory_order_relaxed);
    if (v > max.load(std::memory_order_relaxed)) max.store(v, std::memory_order_relaxed);
  }
};

struct ServerStats {
  // relaxed everywhere: statistics only, nothing is published through them.
  std::atomic<uint64_t> bytes_read{0};           // from storage: mip ranges, headers, OIIO's reads
  std::atomic<uint64_t> bytes_loaded{0};         // payload bytes of mips loaded from storage (kOk misses)
  std::atomic<uint64_t> bytes_served_cached{0};  // payload bytes served from the RAM cache (dispatcher only)
  std::atomic<uint64_t> loads_ok{0};             // misses answered kOk
  std::atomic<uint64_t> hits_ok{0};              // hits answered kOk (dispatcher only)
  std::atomic<uint64_t> pages_ok{0};             // pages of page files answered kOk (not in the counts above)
  std::atomic<uint64_t> page_bytes_read{0};      // their bytes: one exact read each (not in bytes_read)
  std::atomic<uint64_t> not_found{0};
  std::atomic<uint64_t> corrupt{0};
  std::atomic<uint64_t> io_errors{0};
  std::atomic<uint64_t> cancelled{0};
  std::atomic<uint64_t> rate_limit_wait_us{0};  // time workers slept in the token bucket
  QueueGauge pending;                           // requests in the scheduler's heap
  QueueGauge in_flight;                         // loads handed to workers
  QueueGauge overflow;                          // completions waiting for room in the completion ring
  // Recorded by the dispatcher alone (record_one_writer()).
  LatencyHistogram hit_latency;   // request taken off the ring → completion pushed, RAM-cache hits
  LatencyHistogram miss_latency;  // the same for loads from storage
  // Kernel crossings of the dispatcher and the workers (issue 29): per served mip in the report.
  SyscallCounter syscalls;

  void add(std::atomic<uint64_t>& counter, uint64_t v) { counter.fetch_add(v, std::memory_order_relaxed); }
  // add() for a counter only one thread ever writes (the dispatcher's per-hit counters): a plain load and
  // store, no locked read-modify-write (see LatencyHistogram::record_one_writer()).
  static void add_one_writer(std::atomic<uint64_t>& counter, uint64_t v) {
    counter.store(counter.load(std::memory_order_relaxed) + v, std::memory_order_relaxed);
  }
};

// Bytes read from storage ÷ bytes of mips delivered from storage (1.0 = exact reads; 0 when nothing loaded).
double read_amplification(const ServerStats& s);
// A multi-line human-readable report (for the log).
std::string format_stats(const ServerStats& s, const MipCacheStats& cache);

}  // namespace texstream::server
