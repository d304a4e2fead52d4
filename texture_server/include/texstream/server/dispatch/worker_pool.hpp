#pragma once
// A few threads doing the slow part of a load (storage reads and the copy into a slot) so that the
// dispatcher thread, which alone touches the rings, never blocks on I/O. Sized by server.worker_threads
// (2 by default: the 2-core machine of DESIGN.md). The dispatcher submits a job only when a worker is idle,
// so the scheduler's heap, not this queue, decides what runs next (a request still pending can be
// superseded; one handed here has started).
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <span>
#include <thread>
#include <vector>

#include "texstream/common/scene_format.hpp"
#include "texstream/common/syscall_count.hpp"
#include "texstream/protocol/records.hpp"
#include "texstream/protocol/shm_atomic.hpp"
#include "texstream/server/dispatch/request_scheduler.hpp"

namespace texstream::server {

struct LoadJob {
  LoadRequest request;
  scene::TextureRecord record;
  uint32_t slot;
};

struct LoadResult {
  CompletionRecord completion;
  uint32_t slot;         // the slot the job held, whatever its status
  uint64_t received_ns;  // the request's, for the latency histogram
  LoadRequest request;   // the job's request (a local attempt that found the mip remote is handed on with it)
};

class WorkerPool {
 public:
  using Work = std::function<CompletionRecord(const LoadJob&)>;
  // `on_result` runs on the worker thread after each result is queued (the server wakes its dispatcher).
  // `loading` (ServerBlock::loading, or part of it): worker i stores its job's texture id + 1 in loading[i]
  // while the job runs and 0 after, so that the renderer can tell which texture a crashed server was
  // loading; workers beyond loading.size() are not recorded. The workers count their kernel crossings into
  // `syscalls` (the process's counter when null).
  WorkerPool(uint32_t threads, Work work, std::function<void()> on_result, std::span<ShmAtomic<uint32_t>> loading = {},
             SyscallCounter* syscalls = nullptr);
  ~WorkerPool();  // finishes the jobs already started, drops the others, joins
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  void submit(const LoadJob& job);
  // Appends every finished result to `out` (the dispatcher keeps `out` between calls: no allocation when warm).
  void take_results(std::vector<LoadResult>& out);
  uint32_t threads() const { return static_cast<uint32_t>(threads_.size()); }
  // True when take_results() would return something (a lock-free peek for the dispatcher's spin). seq_cst,
  // as the store in worker_main: the dispatcher's sleeping-flag handshake (server.cpp) needs a total order.
  bool results_ready() const { return ready_.load(std::memory_order_seq_cst) > 0; }

 private:
  void worker_main(uint32_t index);

  Work work_;
  std::span<ShmAtomic<uint32_t>> loading_;
  std::function<void()> on_result_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<LoadJob> jobs_;
  std::vector<LoadResult> results_;
  bool stopping_ = false;
  uint32_t idle_ = 0;  // workers blocked in cv_.wait (under mutex_): a notify wakes one only then
  SyscallCounter* syscalls_;
  std::atomic<uint32_t> ready_{0};  // results_.size(), readable without the lock
  std::vector<std::thread> threads_;
};

}  // namespace texstream::server
