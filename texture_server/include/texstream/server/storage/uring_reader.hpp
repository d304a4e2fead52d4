#pragma once
// One io_uring per thread that reads texture files (the dispatcher, each load worker), for the miss path's
// kernel crossings (issue 29): open, read and close of a file are one linked submission, one io_uring_enter,
// where they were three system calls. Direct descriptors (a registered, sparse file table of one slot) let the
// read and the close name the file the open makes in the same submission.
//
// The read is RWF_NOWAIT: it takes only what the page cache holds and never blocks the calling thread on a
// disk or on a FIFO put in a texture's place; anything it cannot do at once comes back as kWouldBlock and
// the caller reads the ordinary way (PosixStorage's pread path), which also words every other error.
// docs/design/syscalls.md.
#include <sys/uio.h>

#include <cstdint>
#include <span>

namespace texstream::server {

struct UringRead {
  enum class Outcome : uint8_t {
    kOk,          // `bytes` read (fewer only at the end of the file)
    kOpenFailed,  // the open failed with `error` (errno)
    kWouldBlock,  // not (all) in the page cache, or not a regular file: read the ordinary way from `bytes` on
    kFailed,      // the read failed with `error` (errno)
  };
  Outcome outcome = Outcome::kFailed;
  uint64_t bytes = 0;
  int error = 0;
};

class UringReader {
 public:
  // The calling thread's reader, made on first use; nullptr where io_uring is unavailable or forbidden
  // (an old kernel, seccomp, kernel.io_uring_disabled) or switched off (set_enabled(false)): then every
  // read goes the ordinary way.
  static UringReader* for_this_thread();
  // Process-wide switch (server.io_uring); readers already made stay until their thread ends.
  static void set_enabled(bool enabled);
  static bool enabled();
  // Whether a reader can be made on this machine (the tests choose their expectations by it).
  static bool available();

  ~UringReader();
  UringReader(const UringReader&) = delete;
  UringReader& operator=(const UringReader&) = delete;

  // openat(dir, name) + readv(parts, offset) + close, one submission. `dir` may be AT_FDCWD with a full path.
  UringRead open_read_close(int dir, const char* name, std::span<const iovec> parts, uint64_t offset);

 private:
  UringReader() = default;
  bool init();
  struct Ring;
  Ring* ring_ = nullptr;
};

}  // namespace texstream::server
