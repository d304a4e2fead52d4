#include "texstream/server/storage/uring_reader.hpp"

#include <fcntl.h>
#include <liburing.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <memory>
#include <string_view>

#include "texstream/common/syscall_count.hpp"

namespace texstream::server {

namespace {
// TEXSTREAM_IO_URING=0 switches it off for the process (a comparison, or a kernel whose io_uring misbehaves).
bool enabled_at_start() {
  const char* v = std::getenv("TEXSTREAM_IO_URING");
  return v == nullptr || std::string_view(v) != "0";
}
std::atomic<bool> g_enabled{enabled_at_start()};
// The one direct-descriptor slot a chain uses: opened, read and closed within one submission.
constexpr unsigned kSlot = 0;
constexpr unsigned kEntries = 8;
}  // namespace

struct UringReader::Ring {
  io_uring ring{};
};

void UringReader::set_enabled(bool enabled) { g_enabled.store(enabled, std::memory_order_relaxed); }
bool UringReader::enabled() { return g_enabled.load(std::memory_order_relaxed); }

UringReader* UringReader::for_this_thread() {
  if (!enabled()) return nullptr;
  // A thread that failed to make one does not try again (each try is a system call).
  thread_local std::unique_ptr<UringReader> reader;
  thread_local bool tried = false;
  if (!tried) {
    tried = true;
    auto r = std::unique_ptr<UringReader>(new UringReader());
    if (r->init()) reader = std::move(r);
  }
  return reader.get();
}

bool UringReader::available() {
  UringReader r;
  return r.init();
}

bool UringReader::init() {
  auto ring = std::make_unique<Ring>();
  if (io_uring_queue_init(kEntries, &ring->ring, 0) != 0) return false;
  if (io_uring_register_files_sparse(&ring->ring, 1) != 0) {
    io_uring_queue_exit(&ring->ring);
    return false;
  }
  ring_ = ring.release();
  return true;
}

UringReader::~UringReader() {
  if (ring_ == nullptr) return;
  io_uring_queue_exit(&ring_->ring);
  delete ring_;
}

UringRead UringReader::open_read_close(int dir, const char* name, std::span<const iovec> parts, uint64_t offset) {
  io_uring* ring = &ring_->ring;
  io_uring_sqe* open = io_uring_get_sqe(ring);
  io_uring_sqe* read = io_uring_get_sqe(ring);
  io_uring_sqe* close = io_uring_get_sqe(ring);
  if (open == nullptr || read == nullptr || close == nullptr) return UringRead{UringRead::Outcome::kWouldBlock, 0, 0};
  // O_NONBLOCK as PosixStorage's open: a FIFO in a texture's place opens at once (and its read would block).
  // No O_CLOEXEC: a direct descriptor is no descriptor of the process (the kernel refuses the flag, EINVAL).
  io_uring_prep_openat_direct(open, dir, name, O_RDONLY | O_NONBLOCK, 0, kSlot);
  open->flags |= IOSQE_IO_LINK;
  open->user_data = 1;
  io_uring_prep_readv2(read, static_cast<int>(kSlot), parts.data(), static_cast<unsigned>(parts.size()), offset,
                       RWF_NOWAIT);
  // Hard link: the close runs whatever the read did (a short read or an error would cancel a soft link's
  // successor and leave the slot occupied).
  read->flags |= IOSQE_FIXED_FILE | IOSQE_IO_HARDLINK;
  read->user_data = 2;
  io_uring_prep_close_direct(close, kSlot);
  close->user_data = 3;
  count_syscall(Syscall::kIoUring);
  int submitted;
  do {
    submitted = io_uring_submit_and_wait(ring, 3);
  } while (submitted == -EINTR);
  UringRead out{UringRead::Outcome::kFailed, 0, 0};
  int open_res = 0, read_res = -ECANCELED;
  unsigned seen = 0;
  while (seen < 3) {
    io_uring_cqe* cqe = nullptr;
    int r = io_uring_peek_cqe(ring, &cqe);
    if (r == -EAGAIN) {
      // Not all completions posted yet (the submit returned early): wait for the rest.
      count_syscall(Syscall::kIoUring);
      r = io_uring_wait_cqe(ring, &cqe);
    }
    if (r != 0) {
      if (r == -EINTR) continue;
      return UringRead{UringRead::Outcome::kWouldBlock, 0, 0};
    }
    if (cqe->user_data == 1) open_res = cqe->res;
    if (cqe->user_data == 2) read_res = cqe->res;
    io_uring_cqe_seen(ring, cqe);
    ++seen;
  }
  if (open_res < 0) return UringRead{UringRead::Outcome::kOpenFailed, 0, -open_res};
  if (read_res >= 0) {
    out.outcome = UringRead::Outcome::kOk;
    out.bytes = static_cast<uint64_t>(read_res);
    return out;
  }
  // EAGAIN: not in the page cache (RWF_NOWAIT) or a FIFO; EOPNOTSUPP: a file system without NOWAIT reads;
  // anything else is worded by the ordinary read, which meets it again.
  return UringRead{UringRead::Outcome::kWouldBlock, 0, -read_res};
}

}  // namespace texstream::server
