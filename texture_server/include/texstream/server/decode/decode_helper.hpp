#pragma once
// One texstream-decode process (decode_channel.hpp) and the server's side of one decode through it.
//
// The helper reads nothing itself: every byte OpenImageIO wants comes back over the channel as a kRead that
// this side serves from the caller's StorageFile, so reads stay counted, rate-limited and fault-injectable,
// and work for any storage the server has. A helper that dies, hangs past the timeout, or breaks the protocol
// fails that one decode with an error naming the file and is killed; the pool starts a new one on next use.
#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"
#include "texstream/server/decode/decode_channel.hpp"
#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

class DecodeHelper {
 public:
  // Starts `exe` with its end of a socket pair as fd 3. Errors: kIo naming the executable.
  static Result<std::unique_ptr<DecodeHelper>> spawn(const std::filesystem::path& exe);
  // Closes the channel (the helper exits on EOF) and reaps the process; SIGKILL if it does not exit at once.
  ~DecodeHelper();
  DecodeHelper(const DecodeHelper&) = delete;
  DecodeHelper& operator=(const DecodeHelper&) = delete;

  // Decodes mip `level` of `file` (named `path`) into `out` (expected.width * expected.height * 4 bytes).
  // `bytes_read` gets what was read from storage, also on failure. `timeout` bounds each wait for the helper.
  // A file error (kCorrupt, kIo, ...) leaves the helper usable; after any other failure usable() is false.
  // helper_failed() then tells whether the helper itself failed on this file (see there).
  Status decode(StorageFile& file, const std::filesystem::path& path, uint32_t level, Extent2D expected,
                std::span<std::byte> out, uint64_t& bytes_read, std::chrono::milliseconds timeout);
  // False once the helper failed, exited or broke the protocol: the pool drops it.
  bool usable();
  // True when the last decode() ended because the helper failed while it held the file: it died (a signal, an
  // exit), broke the protocol, or hung past the timeout after it had read from the file. False after a
  // success, an error the helper reported itself (the file's own fault: kCorrupt, kIo, ...), a helper found
  // dead before it was sent the file (killed from outside while idle), and a timeout before its first read
  // (a helper slow to start on a loaded machine): nothing to blame the file for. The pool quarantines on it.
  bool helper_failed() const { return helper_failed_; }
  pid_t pid() const { return pid_; }

 private:
  DecodeHelper(pid_t pid, DecodeChannel channel) : pid_(pid), channel_(std::move(channel)) {}
  // Kills and reaps the helper; returns how it ended ("killed by signal 11 (Segmentation fault)", ...).
  std::string kill_and_reap();
  Status serve_read(StorageFile& file, const DecodeFrame& request, uint64_t& bytes_read);

  pid_t pid_ = -1;
  DecodeChannel channel_;
  bool broken_ = false;
  bool helper_failed_ = false;
  std::vector<std::byte> read_buffer_;  // reused across reads: no allocation per kRead once grown
};

}  // namespace texstream::server
