// texstream-bench server [--quick] [--scene DIR] [--memory-minutes M]
//
// The texture server running in this process (a thread) against a real shared segment; the bench plays the
// renderer (pushes requests, polls completions, releases slots). Everything is measured in one run, as
// ratios against baselines measured in the same run (DESIGN.md "Determinism and measurement"):
//   1. memcpy of exactly the hit set's mips, vs cache hits into staging slots        → hit_vs_memcpy
//      (alternating passes of each, so that both see the same machine load)
//   2. plain sequential read() of whole texture files (page cache warm), vs misses   → miss_vs_read, read_amp
//      (21 rounds, 15 without --quick: a fresh server's misses between two read() passes; the median round)
//   3. request→completion latency p50/p99 (hits, misses) with a window of kLatencyWindow requests
//   4. a realistic access trace (the scene's camera path, a renderer with a bounded GPU cache, Algorithm 1:
//      one mip per texture per cycle, coarsest first) replayed through our server and through OpenImageIO's
//      ImageCache with the same byte budget → hit rates, throughput ratio, renderer polling cost per frame
//   5. LRU vs level-aware (seed 002 Eq. 4) hit rates on the same trace
//   6. memory: the texstream-server process (not a thread: its own RSS) under a random workload over a
//      texture set ≥ 4x the cache; peak RSS vs budget + staging + 64 MB
// The scene is generated with texstream-gen (rgba8, so both caches hold the same bytes per mip) unless
// --scene is given.
#include <fcntl.h>
#include <pthread.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#if TEXSTREAM_BENCH_OIIO
#include <OpenImageIO/imagecache.h>
#endif
#include <fmt/format.h>
#include <linux/perf_event.h>
#include <spdlog/spdlog.h>
#include <sys/ioctl.h>
#include <sys/syscall.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <future>
#include <memory>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "bench_registry.hpp"
#include "bench_util.hpp"
#include "texstream/common/camera_path.hpp"
#include "texstream/common/config.hpp"
#include "texstream/common/cpu_relax.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/liveness.hpp"
#include "texstream/protocol/renderer_endpoint.hpp"
#include "texstream/protocol/segment.hpp"
#include "texstream/server/cache/level_eviction_policy.hpp"
#include "texstream/server/cache/lru_eviction_policy.hpp"
#include "texstream/server/cache/mip_cache.hpp"
#include "texstream/server/dispatch/server.hpp"
#include "texstream/server/load/mip_loader.hpp"
#include "texstream/server/storage/posix_storage.hpp"

namespace fs = std::filesystem;

namespace texstream::bench {
namespace {

using server::MipKey;

// Requests outstanding while measuring latency: a renderer's cycle sends a batch and polls once per frame;
// a small window measures service time rather than the queueing of a saturated pipeline.
constexpr uint32_t kLatencyWindow = 4;
// Staging pool of the bench's segment: the protocol defaults (config.hpp: 32 slots of 1 MiB).
constexpr uint32_t kSlotCount = 32;
constexpr uint64_t kSlotBytes = 1u << 20;

struct Options {
  bool quick = false;
  fs::path scene;
  double memory_minutes = -1;  // < 0: the default for the mode
  uint32_t textures = 0;       // generated scene size (0: the default for the mode)
  // --profile-misses N: before the misses phase, stream the miss set N more times, each through a fresh
  // server (cold cache, warm arena), so that a profiler sees the miss stream's dispatcher for long enough
  // (one stream is ~20 ms). Not counted in any result.
  uint32_t profile_misses = 0;
  // --miss-rounds N: rounds of the misses phase (0: the mode's default).
  uint32_t miss_rounds = 0;
  // --phases memory,hits,misses,trace: run only these (profiling one phase); skipped phases report 0.
  std::string phases = "memory,hits,misses,trace";
  bool runs(const char* phase) const {
    return ("," + phases + ",").find(std::string(",") + phase + ",") != std::string::npos;
  }
};

struct Request {
  uint32_t texture;
  uint32_t mip;
  float priority;
};
using Cycle = std::vector<Request>;

uint64_t now_ns() {
  return static_cast<uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
          .count());
}

uint64_t rss_bytes(pid_t pid) {
  std::ifstream f(fmt::format("/proc/{}/statm", pid));
  uint64_t size = 0, resident = 0;
  f >> size >> resident;
  return resident * static_cast<uint64_t>(sysconf(_SC_PAGESIZE));
}

// The machine's cost of one bare system call (getppid, which no library caches): what a kernel crossing
// costs here. ~0.1 us on bare metal, 1.2 us measured on a paravirtualised guest (issue 29).
double syscall_ns() {
  constexpr int kCalls = 100'000;
  double best = 1e9;
  for (int round = 0; round < 3; ++round) {  // the best of three: a neighbour only ever adds time
    const uint64_t t0 = now_ns();
    for (int i = 0; i < kCalls; ++i) (void)syscall(SYS_getppid);
    best = std::min(best, static_cast<double>(now_ns() - t0) / kCalls);
  }
  return best;
}

// The kernel's own count of the system calls entered by the thread that opens it and by the threads that
// thread creates afterwards (perf tracepoint raw_syscalls:sys_enter, inherited): the check of the server's
// own count (syscall_count.hpp), which misses what libraries do. Needs tracefs mounted (perf mounts it) and
// perf permission (root, or kernel.perf_event_paranoid <= 1); otherwise why() says what was missing.
class KernelSyscallMeter {
 public:
  KernelSyscallMeter() {
    uint64_t id = 0;
    for (const char* path : {"/sys/kernel/tracing/events/raw_syscalls/sys_enter/id",
                             "/sys/kernel/debug/tracing/events/raw_syscalls/sys_enter/id"}) {
      std::ifstream f(path);
      if (f >> id) break;
      id = 0;
    }
    if (id == 0) {
      why_ = "no tracefs with raw_syscalls (mount tracefs on /sys/kernel/tracing, or run perf once)";
      return;
    }
    perf_event_attr attr{};
    attr.size = sizeof attr;
    attr.type = PERF_TYPE_TRACEPOINT;
    attr.config = id;
    attr.inherit = 1;  // the threads this one starts (the server's workers) count too
    attr.disabled = 0;
    fd_ = static_cast<int>(syscall(SYS_perf_event_open, &attr, 0, -1, -1, 0));
    if (fd_ < 0) why_ = std::string("perf_event_open: ") + std::strerror(errno);
  }
  ~KernelSyscallMeter() {
    if (fd_ >= 0) ::close(fd_);
  }
  KernelSyscallMeter(const KernelSyscallMeter&) = delete;
  KernelSyscallMeter& operator=(const KernelSyscallMeter&) = delete;
  std::optional<uint64_t> read() const {
    uint64_t v = 0;
    if (fd_ < 0 || ::read(fd_, &v, sizeof v) != static_cast<ssize_t>(sizeof v)) return std::nullopt;
    return v;
  }
  const std::string& why() const { return why_; }

 private:
  int fd_ = -1;
  std::string why_;
};

// ---------------------------------------------------------------------------------------------------------
// The renderer's side of one segment, with the server running in a thread of this process.
class Harness {
 public:
  // `meter_kernel`: count the server threads' system calls with the kernel too (kernel_syscalls()).
  static std::unique_ptr<Harness> start(const fs::path& scene, const ServerConfig& config, bool meter_kernel = false) {
    static int counter = 0;
    auto h = std::unique_ptr<Harness>(new Harness());
    SegmentParams params;
    params.slot_count = kSlotCount;
    params.slot_bytes = kSlotBytes;
    auto seg = Segment::create(fmt::format("texstream-bench-{}-{}", getpid(), counter++), params);
    if (!seg.ok()) {
      std::fprintf(stderr, "server bench: %s\n", seg.error().message.c_str());
      return nullptr;
    }
    h->segment_ = std::move(seg).value();
    h->endpoint_ = RendererEndpoint(*h->segment_);
    // The server is made on its dispatcher thread, so that a kernel syscall meter opened there first counts
    // the workers it starts too (and nothing of this, the client's, thread).
    std::promise<std::string> made;
    std::future<std::string> made_result = made.get_future();
    h->thread_ = std::thread([p = h.get(), &scene, &config, &made, meter_kernel] {
      pthread_setname_np(pthread_self(), "ts-dispatcher");  // perf report --comm ts-dispatcher
      p->tid_.store(gettid(), std::memory_order_release);
      if (meter_kernel) p->kernel_meter_ = std::make_unique<KernelSyscallMeter>();
      auto server = server::Server::create(*p->segment_, scene, config, p->storage_);
      if (!server.ok()) {
        made.set_value(server.error().message);
        return;
      }
      p->server_ = std::move(server).value();
      made.set_value("");
      p->server_->run(p->stop_);
    });
    if (const std::string error = made_result.get(); !error.empty()) {
      std::fprintf(stderr, "server bench: %s\n", error.c_str());
      h->thread_.join();
      return nullptr;
    }
    return h;
  }

  // The real texstream-server executable (next to this binary) as a child process instead of a thread: the
  // memory phase measures the resident set of the server process alone.
  static std::unique_ptr<Harness> start_process(const fs::path& scene, int64_t cache_bytes) {
    static int counter = 0;
    auto h = std::unique_ptr<Harness>(new Harness());
    SegmentParams params;
    params.slot_count = kSlotCount;
    params.slot_bytes = kSlotBytes;
    auto seg = Segment::create(fmt::format("texstream-bench-proc-{}-{}", getpid(), counter++), params);
    if (!seg.ok()) return nullptr;
    h->segment_ = std::move(seg).value();
    h->endpoint_ = RendererEndpoint(*h->segment_);
    const std::string exe = (fs::read_symlink("/proc/self/exe").parent_path() / "texstream-server").string();
    std::vector<std::string> args{exe,
                                  "--segment",
                                  h->segment_->name(),
                                  "--scene",
                                  scene.string(),
                                  "--spawned",
                                  "--set",
                                  fmt::format("server.ram_cache_bytes={}", cache_bytes),
                                  "--set",
                                  "server.log_level=warn"};
    h->pid_ = fork();
    if (h->pid_ == 0) {
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(exe.c_str(), argv.data());
      _exit(127);
    }
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (h->segment_->server_block().attached.v.load(std::memory_order_acquire) != 1) {
      if (std::chrono::steady_clock::now() > deadline) {
        std::fprintf(stderr, "server bench: %s did not attach within 10 s\n", exe.c_str());
        return nullptr;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return h;
  }

  ~Harness() {
    if (pid_ > 0) {
      kill(pid_, SIGTERM);
      waitpid(pid_, nullptr, 0);
      return;
    }
    stop_ = true;
    Doorbell(*segment_).wake_all();  // the server thread sees stop_ when it wakes
    if (thread_.joinable()) thread_.join();
    server_.reset();
  }

  server::Server& server() { return *server_; }
  pid_t pid() const { return pid_; }
  // CPU time the dispatcher thread has used so far (0 for a server process): a diagnostic of the server's
  // own work per request that a neighbour's load on the shared cores skews much less than wall time.
  double dispatcher_cpu_s() const {
    clockid_t clock;
    timespec ts{};
    if (pid_ > 0 || !thread_.joinable()) return 0;
    if (pthread_getcpuclockid(const_cast<std::thread&>(thread_).native_handle(), &clock) != 0) return 0;
    if (clock_gettime(clock, &ts) != 0) return 0;
    return static_cast<double>(ts.tv_sec) + static_cast<double>(ts.tv_nsec) / 1e9;
  }
  // The dispatcher thread's user and system CPU time in seconds (/proc/self/task/<tid>/stat, clock ticks):
  // where a miss's time goes, the kernel's reads or our own code. {0, 0} for a server process.
  std::pair<double, double> dispatcher_user_sys_s() const {
    const pid_t tid = tid_.load(std::memory_order_acquire);
    if (pid_ > 0 || tid == 0) return {0, 0};
    std::ifstream f(fmt::format("/proc/self/task/{}/stat", tid));
    std::string stat;
    std::getline(f, stat);
    const size_t paren = stat.rfind(')');  // the name may hold spaces; fields 3.. follow it
    if (paren == std::string::npos) return {0, 0};
    std::istringstream in(stat.substr(paren + 2));
    std::string field;
    double utime = 0, stime = 0;
    for (int i = 3; i <= 15 && in >> field; ++i) {
      if (i == 14) utime = std::atof(field.c_str());
      if (i == 15) stime = std::atof(field.c_str());
    }
    const double tick = static_cast<double>(sysconf(_SC_CLK_TCK));
    return {utime / tick, stime / tick};
  }
  const ServerBlock& server_block() const { return segment_->server_block(); }
  uint32_t slots() const { return kSlotCount; }
  // The kernel's count of the server threads' system calls (start(..., meter_kernel = true)), or why not.
  std::optional<uint64_t> kernel_syscalls() const { return kernel_meter_ ? kernel_meter_->read() : std::nullopt; }
  std::string kernel_meter_why() const { return kernel_meter_ ? kernel_meter_->why() : "not asked"; }

  // Pushes one load; false when the request ring is full.
  bool push(uint32_t texture, uint32_t mip, uint64_t generation, float priority) {
    return endpoint_.push_load(TextureId(texture), MipLevel(mip), Generation(generation), priority);
  }

  // The doorbell after a batch of pushes (the renderer's protocol: bump, then wake a sleeping server).
  void ring() { endpoint_.ring(); }
  void wait_for_completions(std::chrono::microseconds timeout) { endpoint_.wait_for_completions(timeout); }

  // Pops every completion now waiting; calls on(c) for each, then hands kOk slots back. Returns how many.
  template <class F>
  uint32_t poll(F&& on) {
    uint32_t n = 0;
    endpoint_.flush_releases();
    while (std::optional<CompletionRecord> c = endpoint_.poll()) {
      ++n;
      on(*c);
      if (c->status == static_cast<uint32_t>(CompletionStatus::kOk)) endpoint_.release(SlotIndex(c->slot));
    }
    endpoint_.flush_releases();
    endpoint_.ring();
    return n;
  }

 private:
  Harness() = default;

  std::unique_ptr<Segment> segment_;
  RendererEndpoint endpoint_;  // the renderer's end, as StreamClient uses it
  server::PosixStorage storage_;
  std::unique_ptr<server::Server> server_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  std::atomic<pid_t> tid_{0};  // the dispatcher thread's id, once it runs
  std::unique_ptr<KernelSyscallMeter> kernel_meter_;
  pid_t pid_ = 0;  // start_process(): the server child
};

struct StreamResult {
  double seconds = 0;
  uint64_t bytes = 0;  // payload bytes of kOk completions
  uint64_t completions = 0;
  uint64_t failures = 0;  // anything but kOk
  std::vector<double> latency_us;
  std::vector<double> poll_us;  // duration of each poll() that found completions (the renderer's per-frame cost)
};

// Streams `requests` in order with at most `window` outstanding (window ≤ slots); one generation.
// `record_poll_cost`: time each poll that finds completions (StreamResult::poll_us, the trace's renderer
// polling cost per frame). Off for the throughput phases, which do not report it: two clock reads per poll
// were ~1/5 of the bench thread's own samples in the hit phase (perf), time the server then waited for the
// next requests and slot releases (the dispatcher yielded ~18 % of its samples).
// Polls that find nothing spin this long before the client sleeps on the completion bell: a miss takes
// ~3-30 us, and a sleep costs the server a futex wake per publish (one per texture when it was 64 polls).
constexpr uint64_t kClientSpinNs = 50'000;

StreamResult stream(Harness& h, const std::vector<Request>& requests, uint32_t window, uint64_t generation,
                    bool record_latency, bool record_poll_cost = false) {
  StreamResult out;
  std::unordered_map<uint64_t, uint64_t> pushed_at;  // key → push time
  size_t next = 0;
  uint32_t outstanding = 0;
  const uint64_t t0 = now_ns();
  uint64_t idle_since = 0;  // when polls began to find nothing (0: the last found something)
  while (next < requests.size() || outstanding > 0) {
    while (next < requests.size() && outstanding < window) {
      const Request& r = requests[next];
      // Only a latency run keeps per-request push times (the bookkeeping would cost the renderer side of a
      // throughput run as much as the server's own per-request work). Request lists hold no duplicates.
      const uint64_t key = MipKey(TextureId(r.texture), MipLevel(r.mip)).value;
      if (!h.push(r.texture, r.mip, generation, r.priority)) break;
      if (record_latency) pushed_at.emplace(key, now_ns());
      ++outstanding;
      ++next;
    }
    h.ring();
    const uint64_t p0 = record_poll_cost ? now_ns() : 0;
    const uint32_t got = h.poll([&](const CompletionRecord& c) {
      if (record_latency) {
        auto it = pushed_at.find(MipKey(TextureId(c.texture_id), MipLevel(c.mip_level)).value);
        if (it != pushed_at.end()) {
          out.latency_us.push_back(static_cast<double>(now_ns() - it->second) / 1e3);
          pushed_at.erase(it);
        }
      }
      --outstanding;
      ++out.completions;
      if (c.status == static_cast<uint32_t>(CompletionStatus::kOk)) {
        out.bytes += c.byte_size;
      } else {
        ++out.failures;
      }
    });
    if (got > 0) {
      if (record_poll_cost) out.poll_us.push_back(static_cast<double>(now_ns() - p0) / 1e3);
      idle_since = 0;
    } else if (idle_since == 0) {
      idle_since = now_ns();
    } else if (now_ns() - idle_since > kClientSpinNs) {
      // As the renderer waits in lock-step frames and preloads: on the completion bell, which costs no system
      // call on either side while completions flow (a yield loop here was ~32,000 sched_yield per round).
      h.wait_for_completions(std::chrono::milliseconds(1));
      idle_since = 0;
    } else {
      cpu_relax();
    }
  }
  out.seconds = static_cast<double>(now_ns() - t0) / 1e9;
  return out;
}

// ---------------------------------------------------------------------------------------------------------
// Scene and workloads.

struct Scene {
  fs::path dir;
  std::vector<scene::TextureRecord> textures;
  scene::MeshData meshes;
  std::optional<CameraPath> path;
};

uint64_t mip_size(const scene::TextureRecord& t, uint32_t mip) {
  return mip_bytes(static_cast<TexelFormat>(t.format), t.width, t.height, mip);
}
uint64_t texture_size(const scene::TextureRecord& t) {
  return mip_chain_offset(static_cast<TexelFormat>(t.format), t.width, t.height, t.mip_count);
}

// Every mip of textures [first, ...) until `budget` bytes, coarsest first per texture (Algorithm 1's order).
std::vector<Request> all_mips_until(const Scene& s, uint32_t first, uint64_t budget, uint32_t* end = nullptr) {
  std::vector<Request> out;
  uint64_t bytes = 0;
  uint32_t t = first;
  for (; t < s.textures.size() && bytes < budget; ++t) {
    const scene::TextureRecord& r = s.textures[t];
    if (mip_size(r, 0) > kSlotBytes) continue;
    for (uint32_t m = r.mip_count; m-- > 0;) out.push_back({t, m, 1.0f});
    bytes += texture_size(r);
  }
  if (end) *end = t;
  return out;
}

// A renderer's access trace along the camera path (see the file comment). Cycle = every 4th frame of 33 ms.
std::vector<Cycle> build_trace(const Scene& s, uint32_t laps, uint64_t gpu_budget) {
  std::vector<Cycle> trace;
  const uint32_t n = static_cast<uint32_t>(s.textures.size());
  std::vector<uint32_t> resident(n);  // resident finest mip; mip_count = nothing resident
  std::vector<uint64_t> last_seen(n, 0);
  for (uint32_t t = 0; t < n; ++t) resident[t] = s.textures[t].mip_count;
  uint64_t gpu_bytes = 0;
  // Screen: 960 px over a 60° FOV (config.hpp render defaults): the angle one pixel spans.
  const double pixel_angle = 2.0 * std::tan(30.0 * M_PI / 180.0) / 960.0;
  constexpr double kCycleS = 4 * 0.0333;
  constexpr size_t kMaxPerCycle = 256;  // stream.max_requests_in_flight default
  uint64_t cycle_no = 0;
  for (uint32_t lap = 0; lap < laps; ++lap) {
    for (double time = 0; time < s.path->duration_s(); time += kCycleS, ++cycle_no) {
      const CameraPose pose = s.path->sample(time);
      const double yaw = pose.yaw_deg * M_PI / 180.0;
      const double fx = std::sin(yaw), fy = std::cos(yaw);
      struct Want {
        uint32_t texture;
        uint32_t mip;
        float priority;
      };
      std::vector<Want> wants;
      for (const scene::MeshRecord& m : s.meshes.meshes) {
        double c[3], size = 0;
        for (int k = 0; k < 3; ++k) {
          c[k] = m.origin[k] + 0.5 * (double(m.bounds_min[k]) + double(m.bounds_max[k])) - pose.position[k];
          size = std::max(size, double(m.bounds_max[k]) - double(m.bounds_min[k]));
        }
        const double dist = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
        const double horiz = std::hypot(c[0], c[1]);
        if (horiz > 1.0 && (c[0] * fx + c[1] * fy) / horiz < std::cos(50.0 * M_PI / 180.0)) continue;  // off-screen
        const scene::TextureRecord& t = s.textures[m.texture_id];
        // The mip whose texel matches one pixel at this distance (mip 0 when closer).
        const double texel_m = std::max(size, 1.0) / std::max(t.width, t.height);
        const double level = std::log2(std::max(1.0, dist * pixel_angle / texel_m));
        const uint32_t want = std::min(t.mip_count - 1, static_cast<uint32_t>(level));
        last_seen[m.texture_id] = cycle_no;
        if (resident[m.texture_id] > want)
          wants.push_back({m.texture_id, want, static_cast<float>(1.0 / (1.0 + dist))});
      }
      std::sort(wants.begin(), wants.end(), [](const Want& a, const Want& b) { return a.priority > b.priority; });
      Cycle cycle;
      for (const Want& w : wants) {
        if (cycle.size() >= kMaxPerCycle) break;
        const uint32_t mip = resident[w.texture] - 1;  // one mip per texture per cycle, coarsest first
        cycle.push_back({w.texture, mip, w.priority});
        gpu_bytes += mip_size(s.textures[w.texture], mip);
        resident[w.texture] = mip;
      }
      // The GPU cache is bounded: drop the textures seen least recently until the budget holds.
      if (gpu_bytes > gpu_budget) {
        std::vector<uint32_t> order;
        for (uint32_t t = 0; t < n; ++t)
          if (resident[t] < s.textures[t].mip_count) order.push_back(t);
        std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return last_seen[a] < last_seen[b]; });
        for (uint32_t t : order) {
          if (gpu_bytes <= gpu_budget * 3 / 4) break;
          const scene::TextureRecord& r = s.textures[t];
          gpu_bytes -= mip_chain_offset(static_cast<TexelFormat>(r.format), r.width, r.height, r.mip_count) -
                       mip_chain_offset(static_cast<TexelFormat>(r.format), r.width, r.height, resident[t]);
          resident[t] = r.mip_count;
        }
      }
      if (!cycle.empty()) trace.push_back(std::move(cycle));
    }
  }
  return trace;
}

// ---------------------------------------------------------------------------------------------------------
// Phases.

// memcpy of exactly the hit set's mips. Sources: private copies of the mips; destinations: slot-sized
// buffers, as the server has. pass() copies the whole set once, adds bytes and seconds to the totals and
// returns the pass's own GB/s.
class MemcpyBaseline {
 public:
  MemcpyBaseline(const Scene& s, const std::vector<Request>& set)
      : dst_(kSlotCount, std::vector<std::byte>(kSlotBytes, std::byte{0})) {
    for (const Request& r : set) src_.emplace_back(mip_size(s.textures[r.texture], r.mip), std::byte{1});
  }
  double pass() {
    const uint64_t t0 = now_ns();
    uint64_t bytes = 0;
    for (size_t k = 0; k < src_.size(); ++k, ++i_) {
      std::memcpy(dst_[i_ % kSlotCount].data(), src_[k].data(), src_[k].size());
      bytes += src_[k].size();
    }
    const uint64_t ns = std::max<uint64_t>(1, now_ns() - t0);
    bytes_ += bytes;
    ns_ += ns;
    return static_cast<double>(bytes) / static_cast<double>(ns);
  }
  double gbps() const { return ns_ == 0 ? 0 : static_cast<double>(bytes_) / static_cast<double>(ns_); }

 private:
  std::vector<std::vector<std::byte>> src_;
  std::vector<std::vector<std::byte>> dst_;
  size_t i_ = 0;
  uint64_t bytes_ = 0;
  uint64_t ns_ = 0;
};

// Plain sequential read() of whole files: what the miss path is compared with.
double read_gbps(const Scene& s, uint32_t first, uint32_t end, uint64_t* bytes_out) {
  std::vector<char> buf(1 << 20);
  uint64_t bytes = 0;
  Stopwatch sw;
  for (uint32_t t = first; t < end; ++t) {
    FILE* f = std::fopen(scene::texture_path(s.dir, TextureId(t)).c_str(), "rb");
    if (!f) continue;
    const int fd = fileno(f);
    ssize_t n;
    while ((n = ::read(fd, buf.data(), buf.size())) > 0) bytes += static_cast<uint64_t>(n);
    std::fclose(f);
  }
  if (bytes_out) *bytes_out = bytes;
  return static_cast<double>(bytes) / sw.seconds() / 1e9;
}

struct OiioResult {
  double hit_rate = 0;
  double seconds = 0;
  uint64_t bytes = 0;
  uint64_t failures = 0;
};

#if TEXSTREAM_BENCH_OIIO
OiioResult replay_oiio(const Scene& s, const std::vector<Cycle>& trace, uint64_t budget) {
  OIIO::ImageCache* ic = OIIO::ImageCache::create(/*shared=*/false);
  ic->attribute("max_memory_MB", static_cast<float>(static_cast<double>(budget) / (1 << 20)));
  ic->attribute("autotile", 0);  // our files are untiled DDS: one tile = one whole mip, as our cache holds
  ic->attribute("max_open_files", 100);
  std::vector<std::byte> buf(kSlotBytes);
  std::vector<std::string> names(s.textures.size());
  OiioResult out;
  uint64_t lookups = 0, misses = 0;
  int created_before = 0;
  Stopwatch sw;
  for (const Cycle& c : trace) {
    for (const Request& r : c) {
      std::string& name = names[r.texture];
      if (name.empty()) name = scene::texture_path(s.dir, TextureId(r.texture)).string();
      const Extent2D e = mip_extent(s.textures[r.texture].width, s.textures[r.texture].height, r.mip);
      const bool ok = ic->get_pixels(OIIO::ustring(name), 0, static_cast<int>(r.mip), 0, static_cast<int>(e.width), 0,
                                     static_cast<int>(e.height), 0, 1, 0, 4, OIIO::TypeDesc::UINT8, buf.data());
      int created = 0;
      ic->getattribute("stat:tiles_created", OIIO::TypeDesc::INT, &created);
      ++lookups;
      if (created != created_before) ++misses;
      created_before = created;
      if (ok) {
        out.bytes += uint64_t{e.width} * e.height * 4;
      } else {
        ++out.failures;
        (void)ic->geterror();
      }
    }
  }
  out.seconds = sw.seconds();
  out.hit_rate = lookups == 0 ? 0 : 1.0 - static_cast<double>(misses) / static_cast<double>(lookups);
  OIIO::ImageCache::destroy(ic, /*teardown=*/true);
  return out;
}
#else
// Built without OpenImageIO (TEXSTREAM_BENCH_SERVER_OIIO=OFF, for a bundle carried to a bare machine): no
// baseline, its figures NaN.
OiioResult replay_oiio(const Scene&, const std::vector<Cycle>&, uint64_t) {
  return OiioResult{std::nan(""), std::nan(""), 0, 0};
}
#endif

// Waits (at most 10 s) until the server's cache arena and its small-payload pool, if it has them, are
// pre-faulted (at idle priority after start; the staging slots are faulted in when the segment is created and
// opened); returns the seconds.
double wait_for_warm_arena(const server::Server& server) {
  const Stopwatch sw;
  for (;;) {
    const server::MipCacheStats cs = server.cache_stats();
    const bool warm = cs.arena_warm_bytes >= cs.arena_bytes && cs.small_pool_warm_bytes >= cs.small_pool_prefault;
    if (warm || sw.seconds() > 10.0) return sw.seconds();
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

// A multi-line report, each line indented under a phase's output.
void print_indented(const std::string& report) {
  size_t pos = 0;
  while (pos < report.size()) {
    const size_t nl = report.find('\n', pos);
    std::printf("    %s\n", report.substr(pos, nl - pos).c_str());
    if (nl == std::string::npos) break;
    pos = nl + 1;
  }
}

struct OursResult {
  double hit_rate = 0;
  StreamResult stream;
};

OursResult replay_ours(const Scene& s, const std::vector<Cycle>& trace, ServerConfig config) {
  OursResult out;
  auto h = Harness::start(s.dir, config);
  if (!h) return out;
  wait_for_warm_arena(h->server());  // as a server that has been up for a moment
  const uint64_t t0 = now_ns();
  uint64_t generation = 1;
  for (const Cycle& c : trace) {
    StreamResult r = stream(*h, c, h->slots(), generation++, false, /*record_poll_cost=*/true);
    out.stream.bytes += r.bytes;
    out.stream.completions += r.completions;
    out.stream.failures += r.failures;
    out.stream.poll_us.insert(out.stream.poll_us.end(), r.poll_us.begin(), r.poll_us.end());
  }
  out.stream.seconds = static_cast<double>(now_ns() - t0) / 1e9;
  const server::MipCacheStats cs = h->server().cache_stats();
  out.hit_rate = cs.hits + cs.misses == 0 ? 0 : static_cast<double>(cs.hits) / static_cast<double>(cs.hits + cs.misses);
  std::printf("  our server's statistics after the trace:\n");
  print_indented(h->server().stats_report());
  return out;
}

// The cache alone (no I/O) over the trace: the hit rate a policy gives with `budget` bytes. With `arena`,
// payloads come from the cache's buddy arena (make_payload), so evictions made for lack of a contiguous block
// (fragmentation) count too; the arena is not pre-faulted and its bytes are never written here.
double simulate_policy(const Scene& s, const std::vector<Cycle>& trace, uint64_t budget, const std::string& name,
                       bool arena = false) {
  auto policy = server::make_eviction_policy(name, [&s](MipKey k) {
    const scene::TextureRecord& t = s.textures[k.texture().value];
    return t.mip_count - 1 - std::min(k.mip().value, t.mip_count - 1);
  });
  server::MipCache cache(budget, std::move(policy).value(),
                         server::MipCacheOptions{arena, server::ArenaPrefault::kNone});
  uint64_t generation = 0;
  for (const Cycle& c : trace) {
    cache.advance_clock(++generation);
    for (const Request& r : c) {
      const MipKey key(TextureId(r.texture), MipLevel(r.mip));
      if (cache.lookup(key)) continue;
      std::shared_ptr<server::CachedMip> mip = cache.make_payload(mip_size(s.textures[r.texture], r.mip));
      if (mip) cache.insert(key, std::move(mip));
    }
  }
  const server::MipCacheStats st = cache.stats();
  return static_cast<double>(st.hits) / static_cast<double>(std::max<uint64_t>(1, st.hits + st.misses));
}

// RssAnon / RssFile / RssShmem of a process in MB (/proc/<pid>/status): where its resident set lies.
std::string rss_breakdown(pid_t pid) {
  std::ifstream f(fmt::format("/proc/{}/status", pid));
  std::string line, out;
  while (std::getline(f, line)) {
    if (line.rfind("RssAnon:", 0) == 0 || line.rfind("RssFile:", 0) == 0 || line.rfind("RssShmem:", 0) == 0) {
      const size_t colon = line.find(':');
      out += fmt::format("{}{} {:.1f} MB", out.empty() ? "" : ", ", line.substr(0, colon),
                         std::atof(line.c_str() + colon + 1) / 1024.0);
    }
  }
  return out;
}

struct MemoryResult {
  std::string start_breakdown;
  std::string end_breakdown;
  double end_anon_shmem_mb = 0;
  bool oiio_mapped = false;
  double peak_rss_mb = 0;
  double start_rss_mb = 0;
  double limit_mb = 0;
  double set_mb = 0;
  double cache_mb = 0;
  uint64_t requests = 0;
  double hit_rate = 0;
};

MemoryResult memory_run(const Scene& s, double seconds, uint64_t cache_budget) {
  MemoryResult out;
  out.cache_mb = static_cast<double>(cache_budget) / (1 << 20);
  out.limit_mb = out.cache_mb + static_cast<double>(kSlotCount * kSlotBytes) / (1 << 20) + 64;
  // A texture set at least 4x the cache.
  std::vector<uint32_t> set;
  uint64_t set_bytes = 0;
  for (uint32_t t = 0; t < s.textures.size() && set_bytes < 4 * cache_budget; ++t) {
    if (mip_size(s.textures[t], 0) > kSlotBytes) continue;
    set.push_back(t);
    set_bytes += texture_size(s.textures[t]);
  }
  out.set_mb = static_cast<double>(set_bytes) / (1 << 20);
  auto h = Harness::start_process(s.dir, static_cast<int64_t>(cache_budget));
  if (!h) return out;
  const pid_t pid = h->pid();
  out.start_rss_mb = static_cast<double>(rss_bytes(pid)) / (1 << 20);
  out.start_breakdown = rss_breakdown(pid);
  std::mt19937_64 rng(42);
  uint64_t peak = rss_bytes(pid);
  Stopwatch sw, sample;
  uint64_t generation = 1;
  while (sw.seconds() < seconds) {
    // Batches of random (texture, mip) requests, as cycles of a renderer that looks around at random.
    std::vector<Request> batch;
    for (int i = 0; i < 64; ++i) {
      const uint32_t t = set[rng() % set.size()];
      batch.push_back({t, static_cast<uint32_t>(rng() % s.textures[t].mip_count), 1.0f});
    }
    const StreamResult r = stream(*h, batch, h->slots(), generation++, false);
    out.requests += r.completions;
    if (sample.seconds() > 0.05) {
      peak = std::max(peak, rss_bytes(pid));
      sample.reset();
    }
  }
  peak = std::max(peak, rss_bytes(pid));
  out.peak_rss_mb = static_cast<double>(peak) / (1 << 20);
  out.end_breakdown = rss_breakdown(pid);
  {
    std::ifstream maps(fmt::format("/proc/{}/maps", pid));
    std::string line;
    while (std::getline(maps, line)) out.oiio_mapped |= line.find("libOpenImageIO") != std::string::npos;
  }
  const ServerBlock& b = h->server_block();
  const uint64_t hits = b.ram_cache_hits.v.load(), misses = b.ram_cache_misses.v.load();
  out.hit_rate = static_cast<double>(hits) / static_cast<double>(std::max<uint64_t>(1, hits + misses));
  return out;
}

// ---------------------------------------------------------------------------------------------------------

bool generate_scene(const fs::path& dir, uint32_t textures) {
  const fs::path gen = fs::read_symlink("/proc/self/exe").parent_path() / "texstream-gen";
  // fmt rather than operator+: GCC 12 -O3 warns falsely (-Wrestrict) on some std::string concatenations.
  const std::string cmd =
      fmt::format("'{}' --out '{}' --textures {} --seed 7 --format rgba8 --threads 2 --force > /dev/null", gen.string(),
                  dir.string(), textures);
  std::printf("generating a scene: %s\n", cmd.c_str());
  std::fflush(stdout);
  const int rc = std::system(cmd.c_str());
  return rc == 0;
}

int run_server_bench(const Options& options) {
  const Options* const opt = &options;
  spdlog::set_level(spdlog::level::warn);  // the servers' info lines would drown the report
  const Stopwatch total;
  Scene s;
  fs::path temp;
  if (opt->scene.empty()) {
    temp = fs::temp_directory_path() / fmt::format("texstream-bench-scene-{}", getpid());
    const uint32_t n = opt->textures ? opt->textures : (opt->quick ? 3000 : 6000);
    if (!generate_scene(temp, n)) {
      std::fprintf(stderr, "server bench: texstream-gen failed (is it built next to texstream-bench?)\n");
      return 1;
    }
    // The generator leaves ~177 MB of dirty page-cache pages (--quick) that the kernel writes back over the
    // next seconds, while the phases run: disk I/O and flusher CPU on the 2 shared cores, landing on any phase
    // by chance. Written back now, before anything is measured: the page cache stays warm (the issue measures
    // misses from a warm OS page cache); only the writeback's timing moves, out of the measurements.
    // syncfs (the scene's file system alone) rather than sync (every file system's dirty data).
    if (const int fd = ::open(temp.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC); fd >= 0) {
      ::syncfs(fd);
      ::close(fd);
    }
    s.dir = temp;
  } else {
    s.dir = opt->scene;
  }
  struct Cleanup {
    fs::path dir;
    ~Cleanup() {
      std::error_code ec;
      if (!dir.empty()) fs::remove_all(dir, ec);
    }
  } cleanup{temp};
  {
    auto textures = scene::read_texture_table(s.dir);
    auto meshes = scene::read_meshes(s.dir);
    auto manifest = scene::read_manifest(s.dir);
    if (!textures.ok() || !meshes.ok() || !manifest.ok()) {
      std::fprintf(stderr, "server bench: cannot read scene '%s'\n", s.dir.c_str());
      return 1;
    }
    s.textures = std::move(textures).value();
    s.meshes = std::move(meshes).value();
    auto path = CameraPath::load(s.dir / manifest->camera_path);
    if (!path.ok()) {
      std::fprintf(stderr, "server bench: %s\n", path.error().message.c_str());
      return 1;
    }
    s.path = std::move(path).value();
  }
  uint64_t scene_bytes = 0;
  for (const auto& t : s.textures) scene_bytes += texture_size(t);
  const double bare_syscall_ns = syscall_ns();
  std::printf("this machine: a bare system call (getppid) costs %.0f ns\n", bare_syscall_ns);
  std::printf("scene %s: %zu textures, %.1f MB of mips; 2 server workers, %u slots of %llu KiB\n", s.dir.c_str(),
              s.textures.size(), static_cast<double>(scene_bytes) / 1e6, kSlotCount,
              static_cast<unsigned long long>(kSlotBytes >> 10));
  // Warm the page cache for everything (the issue measures misses from a warm OS page cache).
  read_gbps(s, 0, static_cast<uint32_t>(s.textures.size()), nullptr);

  // 6. Memory: the real server process.
  if (opt->runs("memory")) {
    const double memory_s = opt->memory_minutes >= 0 ? opt->memory_minutes * 60.0 : (opt->quick ? 4.0 : 30.0);
    const uint64_t memory_budget = std::min<uint64_t>(32ull << 20, scene_bytes / 4);
    const MemoryResult mem = memory_run(s, memory_s, memory_budget);
    std::printf(
        "\n[memory] texstream-server process, %.0f s random workload over %.1f MB of textures (%.1fx the cache), "
        "%llu requests, hit rate %.3f\n  server RSS at start %.1f MB, peak %.1f MB; limit = cache %.1f + staging %.1f "
        "+ 64 MB = %.1f MB -> %s\n",
        memory_s, mem.set_mb, mem.set_mb / mem.cache_mb, static_cast<unsigned long long>(mem.requests), mem.hit_rate,
        mem.start_rss_mb, mem.peak_rss_mb, mem.cache_mb, static_cast<double>(kSlotCount * kSlotBytes) / (1 << 20),
        mem.limit_mb, mem.peak_rss_mb <= mem.limit_mb ? "within" : "OVER");
    std::printf("  server at start: %s\n  server at end:   %s\n", mem.start_breakdown.c_str(),
                mem.end_breakdown.c_str());
    std::printf("  OpenImageIO mapped in the server process: %s\n",
                mem.oiio_mapped ? "yes" : "no (decoding runs in texstream-decode helpers)");
    // RssFile is the mapped code of the linked libraries (OpenImageIO pulls in dozens), shared and evictable;
    // the growth under load is what the cache, the staging pool and the allocator add.
    std::printf("  growth under load %.1f MB vs cache + staging + 64 MB = %.1f MB -> %s\n",
                mem.peak_rss_mb - mem.start_rss_mb, mem.limit_mb,
                mem.peak_rss_mb - mem.start_rss_mb <= mem.limit_mb ? "within" : "OVER");
  }

  // 1. Hits vs memcpy.
  const double phase_s = opt->quick ? 1.5 : 5.0;
  ServerConfig config;  // defaults: 2 workers, 256 MiB cache, level policy (config.hpp)
  double memcpy_bw = 0, hit_bw = 0;
  // Per pair (one pass of each) and per round of misses: the summary's ratios are their medians. A neighbour
  // that takes a core or memory bandwidth for a while slows one side of a pair or round only, and only ever
  // slows it: the summed ratio moved with how many such bursts a run happened to catch (miss rounds of one
  // run: 0.56 0.22 0.60 0.56 0.48), the median does not. The summed ratios are printed too.
  std::vector<double> hit_pair_ratios, miss_round_ratios;
  StreamResult hit_lat, miss_lat;
  if (opt->runs("hits")) {
    const std::vector<Request> hit_set = all_mips_until(s, 0, 48ull << 20);
    uint64_t hit_set_bytes = 0;
    for (const Request& r : hit_set) hit_set_bytes += mip_size(s.textures[r.texture], r.mip);
    MemcpyBaseline baseline(s, hit_set);
    auto h = Harness::start(s.dir, config);
    if (!h) return 1;
    wait_for_warm_arena(h->server());           // its idle-priority pre-fault must not run during the measurement
    stream(*h, hit_set, h->slots(), 1, false);  // load them all once: misses
    StreamResult acc;
    Stopwatch sw;
    uint64_t generation = 2;
    // The baseline and the hits alternate, one pass over the set each (a few ms): on a shared machine a
    // neighbour that takes a core for a while then slows both alike. Timed one after the other (1.5 s each),
    // the ratio swung with whatever else ran in either half (memcpy measured 1.1 to 27 GB/s between runs).
    while (sw.seconds() < 2 * phase_s) {
      const double memcpy_pass = baseline.pass();
      StreamResult r = stream(*h, hit_set, h->slots(), generation++, false);
      hit_pair_ratios.push_back(static_cast<double>(r.bytes) / std::max(r.seconds, 1e-9) / 1e9 / memcpy_pass);
      acc.bytes += r.bytes;
      acc.seconds += r.seconds;
      acc.failures += r.failures;
    }
    memcpy_bw = baseline.gbps();
    hit_bw = static_cast<double>(acc.bytes) / acc.seconds / 1e9;
    hit_lat = stream(*h, hit_set, kLatencyWindow, generation++, true);
    const server::MipCacheStats cs = h->server().cache_stats();
    std::printf(
        "\n[hits] %zu mips (%.1f MB) served from the RAM cache repeatedly: %.2f GB/s; memcpy of the same mips "
        "into slot-sized buffers: %.2f GB/s -> summed ratio %.3f; median of %zu alternating pairs %.3f (goal "
        ">= 0.5); %llu hits, %llu failures\n",
        hit_set.size(), static_cast<double>(hit_set_bytes) / 1e6, hit_bw, memcpy_bw, hit_bw / memcpy_bw,
        hit_pair_ratios.size(), percentile(hit_pair_ratios, 50), static_cast<unsigned long long>(cs.hits),
        static_cast<unsigned long long>(acc.failures));
    std::printf("  pair ratios: p10 %.3f, p90 %.3f\n", percentile(hit_pair_ratios, 10),
                percentile(hit_pair_ratios, 90));
  }

  // 2. Misses vs read().
  double miss_bw = 0, read_bw = 0, read_amp = 0;
  double miss_dispatcher_cpu_s = 0;         // diagnostic
  std::vector<double> miss_round_syscalls;  // the server's system calls per mip delivered, per round
  double miss_kernel_syscalls = std::nan("");
  double miss_loads_per_round = 0;  // storage loads (the rest of the miss set comes with their tails)
  std::string miss_syscall_check;
  double miss_dispatcher_user_s = 0, miss_dispatcher_sys_s = 0;  // diagnostic, in clock ticks
  if (opt->runs("misses")) {
    uint32_t end = 0;
    const uint32_t first = static_cast<uint32_t>(s.textures.size() / 2);  // not the hit set's textures
    const std::vector<Request> miss_set = all_mips_until(s, first, opt->quick ? (64ull << 20) : (160ull << 20), &end);
    uint64_t read_bytes = 0;
    read_gbps(s, first, end, nullptr);  // warm
    for (uint32_t k = 0; k < opt->profile_misses; ++k) {
      auto hp = Harness::start(s.dir, config);
      if (!hp) return 1;
      wait_for_warm_arena(hp->server());
      stream(*hp, miss_set, hp->slots(), 1, false);
    }
    // Rounds, each a fresh server (cold cache) streaming the whole miss set between two read() passes over the
    // same files; the summary takes the median round, the sums are printed too. One pass is ~50 ms: on this VM
    // either side alone swung by up to 2x between back-to-back runs (read() 3.9-8.0 GB/s, misses 2.5-3.8 GB/s
    // over 6 runs, each side moving on its own), so a single pass of each decided the ratio by chance. Rounds
    // of one run still spread by 0.1-0.3 and fall in two clusters at times (15 rounds of one run: eleven at
    // 0.36-0.49, four at 0.53-0.68), so a median of 5 moved with how many rounds a run caught of each: 21 rounds
    // in quick mode (~0.1 s each; with 9 the median of back-to-back runs of one build spread 0.49-0.59), 15 in
    // full mode (~0.25 s each).
    const int rounds = opt->miss_rounds > 0 ? static_cast<int>(opt->miss_rounds) : opt->quick ? 21 : 15;
    std::unique_ptr<Harness> h;
    double arena_wait_s = 0, read_s = 0;
    uint64_t read_total = 0;
    StreamResult r;  // summed over the rounds
    for (int k = 0; k < rounds; ++k) {
      h.reset();  // the previous round's server goes first: one arena at a time
      h = Harness::start(s.dir, config);
      if (!h) return 1;
      // A server with a warm cache arena pre-faults it at idle priority after start (cache_arena.hpp): a miss
      // in a server that has been up for a second reads into warm memory. Wait for that (bounded), and say so.
      arena_wait_s = std::max(arena_wait_s, wait_for_warm_arena(h->server()));
      uint64_t before_bytes = 0, after_bytes = 0;
      const double read_before = read_gbps(s, first, end, &before_bytes);
      const double cpu_before = h->dispatcher_cpu_s();
      const auto [user_before, sys_before] = h->dispatcher_user_sys_s();
      const uint64_t syscalls_before = h->server().stats().syscalls.total();
      const StreamResult rk = stream(*h, miss_set, h->slots(), 1, false);
      miss_round_syscalls.push_back(static_cast<double>(h->server().stats().syscalls.total() - syscalls_before) /
                                    static_cast<double>(std::max<uint64_t>(1, rk.completions)));
      miss_dispatcher_cpu_s += h->dispatcher_cpu_s() - cpu_before;
      const auto [user_after, sys_after] = h->dispatcher_user_sys_s();
      miss_dispatcher_user_s += user_after - user_before;
      miss_dispatcher_sys_s += sys_after - sys_before;
      const double read_after = read_gbps(s, first, end, &after_bytes);
      const double read_k_s =
          static_cast<double>(before_bytes) / read_before / 1e9 + static_cast<double>(after_bytes) / read_after / 1e9;
      read_s += read_k_s;
      read_total += before_bytes + after_bytes;
      read_bytes = before_bytes;
      r.bytes += rk.bytes;
      r.seconds += rk.seconds;
      r.failures += rk.failures;
      miss_round_ratios.push_back((static_cast<double>(rk.bytes) / rk.seconds) /
                                  (static_cast<double>(before_bytes + after_bytes) / read_k_s));
    }
    read_bw = static_cast<double>(read_total) / read_s / 1e9;
    miss_bw = static_cast<double>(r.bytes) / r.seconds / 1e9;
    read_amp = server::read_amplification(h->server().stats());
    const std::string miss_report = h->server().stats_report();
    const uint64_t loads_per_round = h->server().stats().loads_ok.load();
    const server::MipCacheStats miss_cache_stats = h->server().cache_stats();  // h goes before the check
    miss_loads_per_round = static_cast<double>(loads_per_round);
    // Latency of misses: other textures, not cached yet, their files warm in the page cache like the miss
    // set's (read once first). Not warmed, they had been read last by the generator, and in full mode with a
    // 10-minute memory phase in between the kernel had dropped them: misses p50 108 us, p99 1529 us, disk reads
    // (13 us / 808 us with a 1-minute phase).
    uint32_t end2 = 0;
    const std::vector<Request> lat_set = all_mips_until(s, end, 8ull << 20, &end2);
    (void)read_gbps(s, end, end2, nullptr);
    miss_lat = stream(*h, lat_set, kLatencyWindow, 2, true);
    // The check: one more round, not timed, with the kernel counting the server threads' system calls (the
    // tracepoint costs every call a little, so the timed rounds run without it).
    {
      h.reset();
      auto checked = Harness::start(s.dir, config, /*meter_kernel=*/true);
      if (!checked) return 1;
      wait_for_warm_arena(checked->server());
      const std::optional<uint64_t> kernel_before = checked->kernel_syscalls();
      const uint64_t ours_before = checked->server().stats().syscalls.total();
      const StreamResult rc = stream(*checked, miss_set, checked->slots(), 1, false);
      const std::optional<uint64_t> kernel_after = checked->kernel_syscalls();
      const uint64_t ours = checked->server().stats().syscalls.total() - ours_before;
      const double mips = static_cast<double>(std::max<uint64_t>(1, rc.completions));
      if (kernel_before && kernel_after) {
        miss_kernel_syscalls = static_cast<double>(*kernel_after - *kernel_before) / mips;
        miss_syscall_check = fmt::format(
            "the kernel's count over one more round (perf raw_syscalls:sys_enter, the server's threads): {} system "
            "calls, {:.3f} per mip; ours {} ({:.3f} per mip)",
            *kernel_after - *kernel_before, miss_kernel_syscalls, ours, static_cast<double>(ours) / mips);
      } else {
        miss_syscall_check = "the kernel's count: unavailable (" + checked->kernel_meter_why() + "); ours " +
                             std::to_string(ours) + " over one more round";
      }
    }
    // Diagnostic: the same misses against a server whose cache is already at its budget (32 MiB, filled with
    // other textures), so every insert evicts and reuses freed memory: the cost of a miss in a server that has
    // been running, without the first touch of never-used cache memory that the cold run above pays.
    double steady_bw = 0;
    std::vector<double> steady_bws;
    {
      ServerConfig steady = config;
      steady.ram_cache_bytes = 32ll << 20;
      auto hs = Harness::start(s.dir, steady);
      if (!hs) return 1;
      // Three streams, each after a refill with other textures (the last stream's misses went out meanwhile),
      // and their median: one stream of ~60 ms moved 0.16-0.36 of read() between runs on this VM.
      const std::vector<Request> refill = all_mips_until(s, 0, 40ull << 20);
      uint64_t generation = 1;
      for (int k = 0; k < 3; ++k) {
        stream(*hs, refill, hs->slots(), generation++, false);
        const StreamResult rs = stream(*hs, miss_set, hs->slots(), generation++, false);
        steady_bws.push_back(static_cast<double>(rs.bytes) / rs.seconds / 1e9);
      }
      steady_bw = percentile(steady_bws, 50);
    }
    // Diagnostic: the same misses through MipLoader alone on this thread (no rings, dispatcher or workers):
    // separates the cost of a load itself from the cost of the pipeline around it.
    double loader_bw = 0;
    {
      ServerBlock block{};
      server::ServerStats stats;
      // With a warm arena, as the server's own cache has one (pre-faulted before the clock starts).
      server::MipCache cache(static_cast<uint64_t>(config.ram_cache_bytes),
                             server::make_eviction_policy("lru", nullptr).value(),
                             server::MipCacheOptions{true, server::ArenaPrefault::kNow});
      server::PosixStorage storage;
      server::MipLoader loader(s.dir, storage, cache, block, stats);
      std::vector<std::byte> slot(kSlotBytes);
      uint64_t bytes = 0;
      Stopwatch lw;
      // As the dispatcher does it: a hit first, else a load that brings the coarse tail along.
      for (const Request& q : miss_set) {
        const server::LoadRequest lr{TextureId(q.texture), MipLevel(q.mip), Generation(1), q.priority, 0};
        CompletionRecord c = loader.serve_cached(lr, s.textures[q.texture], 0, slot);
        if (c.status != static_cast<uint32_t>(CompletionStatus::kOk)) {
          c = loader.load(lr, s.textures[q.texture], 0, slot, /*local_only=*/true, /*read_tail=*/true);
        }
        if (c.status == static_cast<uint32_t>(CompletionStatus::kOk)) bytes += c.byte_size;
      }
      loader_bw = static_cast<double>(bytes) / lw.seconds() / 1e9;
    }
    {
      const server::MipCacheStats& cs = miss_cache_stats;
      if (cs.arena_bytes > 0) {
        std::printf(
            "\n[misses] the server's cache arena: %.1f MB, %.1f MB pre-faulted, and its small-payload pool: %.1f "
            "MB, %.1f MB of it pre-faulted, after %.2f s of waiting before the misses (%llu arena evictions, %llu "
            "fallbacks)",
            static_cast<double>(cs.arena_bytes) / 1e6, static_cast<double>(cs.arena_warm_bytes) / 1e6,
            static_cast<double>(cs.small_pool_capacity) / 1e6, static_cast<double>(cs.small_pool_warm_bytes) / 1e6,
            arena_wait_s, static_cast<unsigned long long>(cs.arena_evictions),
            static_cast<unsigned long long>(cs.arena_fallbacks));
      } else {
        std::printf("\n[misses] the server's cache has no arena (payloads from malloc)");
      }
    }
    const double per_round = static_cast<double>(rounds);
    const double mips_streamed = per_round * static_cast<double>(std::max<size_t>(1, miss_set.size()));
    std::printf(
        "\n[misses] %zu mips of %u textures (%.1f MB delivered, page cache warm) x %d rounds, each a fresh server "
        "between two read() passes: %.2f GB/s; plain sequential read() of the same files (%.1f MB): %.2f GB/s "
        "-> summed ratio %.3f; median of the rounds %.3f (goal >= 0.5); read amplification %.4f (goal <= "
        "1.1); %llu failures\n",
        miss_set.size(), end - first, static_cast<double>(r.bytes) / per_round / 1e6, rounds, miss_bw,
        static_cast<double>(read_bytes) / 1e6, read_bw, miss_bw / read_bw, percentile(miss_round_ratios, 50), read_amp,
        static_cast<unsigned long long>(r.failures));
    std::printf("  ratio per round:");
    for (const double q : miss_round_ratios) std::printf(" %.3f", q);
    std::printf(
        "\n  (diagnostic) the dispatcher thread's CPU time during the misses: %.1f ms of %.1f ms, %.2f us per "
        "mip; in clock ticks %.0f ms user, %.0f ms system\n",
        miss_dispatcher_cpu_s * 1e3, r.seconds * 1e3, miss_dispatcher_cpu_s * 1e6 / mips_streamed,
        miss_dispatcher_user_s * 1e3, miss_dispatcher_sys_s * 1e3);
    std::printf("  the server's statistics after the misses:\n");
    print_indented(miss_report);
    std::printf(
        "  system calls of the server's threads per mip delivered (a fresh server, every mip a miss when asked): "
        "median of the rounds %.3f (goal <= 1), %.2f per storage load (%.0f loads per round; the rest come "
        "with their tails); a bare system call costs %.0f ns here\n  %s\n",
        percentile(miss_round_syscalls, 50),
        percentile(miss_round_syscalls, 50) * static_cast<double>(miss_set.size()) /
            std::max(1.0, miss_loads_per_round),
        miss_loads_per_round, bare_syscall_ns, miss_syscall_check.c_str());
    std::printf(
        "  (diagnostic) the same misses with the cache already full (steady state, 32 MiB): median of %zu "
        "streams %.2f GB/s (",
        steady_bws.size(), steady_bw);
    for (size_t k = 0; k < steady_bws.size(); ++k) std::printf("%s%.2f", k ? " " : "", steady_bws[k]);
    std::printf(") -> ratio %.3f\n", steady_bw / read_bw);
    std::printf(
        "  (diagnostic) the same misses through the loader alone on one thread, no rings: %.2f GB/s, %.2f us "
        "per mip\n",
        loader_bw,
        static_cast<double>(r.bytes) / per_round / 1e3 / loader_bw /
            static_cast<double>(std::max<size_t>(1, miss_set.size())));
  }
  const double hit_p50 = percentile(hit_lat.latency_us, 50), hit_p99 = percentile(hit_lat.latency_us, 99);
  const double miss_p50 = percentile(miss_lat.latency_us, 50), miss_p99 = percentile(miss_lat.latency_us, 99);
  std::printf(
      "\n[latency] request pushed -> completion polled, %u outstanding: hits p50 %.1f us p99 %.1f us (n=%zu); "
      "misses (page cache warm) p50 %.1f us p99 %.1f us (n=%zu)\n",
      kLatencyWindow, hit_p50, hit_p99, hit_lat.latency_us.size(), miss_p50, miss_p99, miss_lat.latency_us.size());

  // 4./5. The realistic trace.
  double oiio_hit_rate = 0, our_hit_rate = 0, throughput_ratio = 0;
  if (opt->runs("trace")) {
    const uint64_t gpu_budget = std::max<uint64_t>(scene_bytes / 8, 4ull << 20);
    const std::vector<Cycle> trace = build_trace(s, opt->quick ? 2 : 3, gpu_budget);
    uint64_t trace_requests = 0, trace_bytes = 0;
    std::unordered_map<uint64_t, uint64_t> distinct;
    for (const Cycle& c : trace) {
      for (const Request& r : c) {
        ++trace_requests;
        trace_bytes += mip_size(s.textures[r.texture], r.mip);
        distinct[MipKey(TextureId(r.texture), MipLevel(r.mip)).value] = mip_size(s.textures[r.texture], r.mip);
      }
    }
    uint64_t distinct_bytes = 0;
    for (const auto& [k, v] : distinct) distinct_bytes += v;
    const uint64_t trace_budget = distinct_bytes / 4;
    std::printf(
        "\n[trace] camera path x%u, renderer GPU cache %.1f MB: %zu cycles, %llu requests, %.1f MB requested, "
        "%zu distinct mips (%.1f MB); both caches get %.1f MB\n",
        opt->quick ? 2u : 3u, static_cast<double>(gpu_budget) / 1e6, trace.size(),
        static_cast<unsigned long long>(trace_requests), static_cast<double>(trace_bytes) / 1e6, distinct.size(),
        static_cast<double>(distinct_bytes) / 1e6, static_cast<double>(trace_budget) / 1e6);
    ServerConfig trace_config;
    trace_config.ram_cache_bytes = static_cast<int64_t>(trace_budget);
    const OursResult ours = replay_ours(s, trace, trace_config);
    const OiioResult oiio = replay_oiio(s, trace, trace_budget);
    const double ours_bw = static_cast<double>(ours.stream.bytes) / ours.stream.seconds / 1e6;
    const double oiio_bw = static_cast<double>(oiio.bytes) / oiio.seconds / 1e6;
    std::printf(
        "  ours (server, %s policy): hit rate %.3f, %.1f MB/s (%.2f s, %llu failures)\n"
        "  OpenImageIO ImageCache (same budget, get_pixels per request): hit rate %.3f, %.1f MB/s (%.2f s, "
        "%llu failures)\n  throughput ours / OpenImageIO = %.2f\n",
        std::string(choice_name(trace_config.cache_policy)).c_str(), ours.hit_rate, ours_bw, ours.stream.seconds,
        static_cast<unsigned long long>(ours.stream.failures), oiio.hit_rate, oiio_bw, oiio.seconds,
        static_cast<unsigned long long>(oiio.failures), ours_bw / oiio_bw);
    std::printf(
        "  renderer polling cost per frame (each poll that found completions, incl. slot releases): mean %.1f us, "
        "p99 %.1f us over %zu polls\n",
        mean(ours.stream.poll_us), percentile(ours.stream.poll_us, 99), ours.stream.poll_us.size());
    std::printf("\n[policy] cache alone over the same trace (hit rate):\n");
    for (const uint64_t budget : {distinct_bytes / 8, distinct_bytes / 4, distinct_bytes / 2}) {
      std::printf("  budget %6.1f MB: lru %.3f  level (seed 002 Eq. 4) %.3f  level with the buddy arena %.3f\n",
                  static_cast<double>(budget) / 1e6, simulate_policy(s, trace, budget, "lru"),
                  simulate_policy(s, trace, budget, "level"), simulate_policy(s, trace, budget, "level", true));
    }
    oiio_hit_rate = oiio.hit_rate;
    our_hit_rate = ours.hit_rate;
    throughput_ratio = ours_bw / oiio_bw;
  }

  std::printf("\ntotal %.1f s\n", total.seconds());
  Summary()
      .add("hit_vs_memcpy", hit_pair_ratios.empty() ? 0 : percentile(hit_pair_ratios, 50))
      .add("miss_vs_read", miss_round_ratios.empty() ? 0 : percentile(miss_round_ratios, 50))
      .add("read_amp", read_amp)
      .add("hit_p99_us", hit_p99)
      .add("miss_p99_us", miss_p99)
      .add("oiio_hit_rate", oiio_hit_rate)
      .add("our_hit_rate", our_hit_rate)
      .add("oiio_throughput_ratio", throughput_ratio)
      .add("syscalls_per_miss", miss_round_syscalls.empty() ? std::nan("") : percentile(miss_round_syscalls, 50))
      .add("syscall_ns", bare_syscall_ns)
      .print();
  return 0;
}

std::function<int()> define_server(CLI::App& app) {
  auto o = std::make_shared<Options>();
  app.add_flag("--quick", o->quick, "the short run (about a minute on the 2-core machine)");
  app.add_option("--scene", o->scene, "a generated scene (default: one generated for the run)");
  app.add_option("--memory-minutes", o->memory_minutes, "length of the memory phase (default: the mode's)");
  app.add_option("--textures", o->textures, "textures of the generated scene (default: 3000, 6000 full)");
  app.add_option("--phases", o->phases, "run only these of memory,hits,misses,trace");
  app.add_option("--profile-misses", o->profile_misses, "stream the miss set N more times first, for a profiler");
  app.add_option("--miss-rounds", o->miss_rounds, "rounds of the misses phase (default: the mode's)");
  return [o] { return run_server_bench(*o); };
}

}  // namespace

TEXSTREAM_BENCH_COMMAND(
    server, "Texture server: RAM-cache hits vs memcpy, misses vs read(), latency, vs OIIO ImageCache, memory",
    define_server);

}  // namespace texstream::bench
