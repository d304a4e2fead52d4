#include "texstream/server/dispatch/worker_pool.hpp"

namespace texstream::server {

WorkerPool::WorkerPool(uint32_t threads, Work work, std::function<void()> on_result,
                       std::span<ShmAtomic<uint32_t>> loading, SyscallCounter* syscalls)
    : work_(std::move(work)),
      loading_(loading),
      on_result_(std::move(on_result)),
      syscalls_(syscalls != nullptr ? syscalls : &process_syscalls()) {
  results_.reserve(64);
  threads_.reserve(threads);
  for (uint32_t i = 0; i < threads; ++i) threads_.emplace_back([this, i] { worker_main(i); });
}

WorkerPool::~WorkerPool() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    jobs_.clear();
  }
  cv_.notify_all();
  for (std::thread& t : threads_) t.join();
}

void WorkerPool::submit(const LoadJob& job) {
  bool wake = false;
  {
    std::lock_guard lock(mutex_);
    jobs_.push_back(job);
    wake = idle_ > 0;
  }
  // Only a blocked worker needs the futex wake; a busy one takes the job when it looks again.
  if (wake) {
    count_syscall(Syscall::kFutexWake);
    cv_.notify_one();
  }
}

void WorkerPool::take_results(std::vector<LoadResult>& out) {
  // No lock when there is nothing to take: the dispatcher asks every pass, and with its misses loaded inline
  // the pool's lock was 10 % of the dispatcher's lock calls (perf probe on pthread_mutex_lock, misses). A
  // worker stores ready_ under the lock right after each push, and only this function resets it (under the
  // lock, after taking everything): a result is never left behind unseen, at worst it waits for the next pass
  // (the worker's on_result_ wakes a sleeping dispatcher, as before).
  if (ready_.load(std::memory_order_acquire) == 0) return;
  std::lock_guard lock(mutex_);
  out.insert(out.end(), results_.begin(), results_.end());
  results_.clear();
  ready_.store(0, std::memory_order_release);  // pairs with results_ready()'s acquire
}

void WorkerPool::worker_main(uint32_t index) {
  const SyscallAccount account(*syscalls_);
  ShmAtomic<uint32_t>* const loading = index < loading_.size() ? &loading_[index] : nullptr;
  for (;;) {
    LoadJob job;
    {
      std::unique_lock lock(mutex_);
      while (!stopping_ && jobs_.empty()) {
        ++idle_;
        count_syscall(Syscall::kFutexWait);
        cv_.wait(lock);
        --idle_;
      }
      if (stopping_) return;
      job = jobs_.front();
      jobs_.pop_front();
    }
    // The read and the copy run with no lock held. Relaxed: the renderer reads the word only after this
    // process died, when every store it made is in the shared page.
    // A page is not charged: its file is no texture of the table (the renderer quarantines textures).
    const bool charge = loading != nullptr && !job.request.page;
    if (charge) loading->v.store(job.request.texture.value + 1, std::memory_order_relaxed);
    const CompletionRecord completion = work_(job);
    if (charge) loading->v.store(0, std::memory_order_relaxed);
    {
      std::lock_guard lock(mutex_);
      results_.push_back({completion, job.slot, job.request.received_ns, job.request});
      // seq_cst: pairs with results_ready() and orders before on_result_'s load of the sleeping flag.
      ready_.store(static_cast<uint32_t>(results_.size()), std::memory_order_seq_cst);
    }
    if (on_result_) on_result_();
  }
}

}  // namespace texstream::server
