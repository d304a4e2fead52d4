#include "texstream/server/decode/decode_helper.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fmt/format.h>

#include <cerrno>
#include <cstring>
#include <thread>

#include "texstream/common/child_process.hpp"

namespace texstream::server {

namespace {

// The helper's end of the socket pair in the helper process (decode/main.cpp reads it from here).
constexpr int kHelperFd = 3;
// How long a helper gets to exit after its channel closed before it is killed.
constexpr auto kExitGrace = std::chrono::milliseconds(200);

Error fail(ErrorCode code, const std::filesystem::path& path, uint32_t level, const std::string& why) {
  // fmt rather than operator+: GCC 12 -O3 warns falsely (-Wrestrict) on some std::string concatenations.
  return make_error(code, fmt::format("'{}': cannot decode mip {}: {}", path.string(), level, why));
}

std::string describe_wait_status(int status) {
  if (WIFSIGNALED(status)) {
    return fmt::format("killed by signal {} ({})", WTERMSIG(status), ::strsignal(WTERMSIG(status)));
  }
  if (WIFEXITED(status)) return fmt::format("exited with status {}", WEXITSTATUS(status));
  return "ended";
}

}  // namespace

Result<std::unique_ptr<DecodeHelper>> DecodeHelper::spawn(const std::filesystem::path& exe) {
  int sv[2];
  // CLOEXEC on both ends: no other child of this process may inherit them (the helper must see EOF when the
  // server goes away); the helper's end reaches it only through the dup2 below, which clears the flag.
  if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv) != 0) {
    return make_error(ErrorCode::kIo, fmt::format("decode helper: socketpair: {}", std::strerror(errno)));
  }
  DecodeChannel mine(sv[0]);
  int theirs = sv[1];
  if (theirs == kHelperFd) {  // dup2 onto itself would keep CLOEXEC: move it out of the way first
    theirs = ::fcntl(sv[1], F_DUPFD_CLOEXEC, kHelperFd + 1);
    ::close(sv[1]);
    if (theirs < 0) return make_error(ErrorCode::kIo, fmt::format("decode helper: fcntl: {}", std::strerror(errno)));
  }
  SpawnOptions options;
  options.fds = {SpawnFd::dup2(theirs, kHelperFd), SpawnFd::open(STDIN_FILENO, "/dev/null", O_RDONLY, 0)};
  // The server's signal mask and handlers (SIGUSR1 for statistics, ...) are not the helper's.
  options.signals.reset = true;
  const std::string exe_string = exe.string();
  const Result<pid_t> spawned = spawn_process({exe_string, "--fd", std::to_string(kHelperFd)}, options);
  ::close(theirs);
  if (!spawned) {
    return make_error(ErrorCode::kIo, fmt::format("cannot start the decode helper: {}", spawned.error().message));
  }
  const pid_t pid = *spawned;
  return std::unique_ptr<DecodeHelper>(new DecodeHelper(pid, std::move(mine)));
}

DecodeHelper::~DecodeHelper() {
  if (pid_ <= 0) return;
  channel_ = DecodeChannel();  // EOF: an idle helper exits by itself
  const auto deadline = std::chrono::steady_clock::now() + kExitGrace;
  int status = 0;
  while (::waitpid(pid_, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > deadline) {
      kill_and_reap();
      return;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
}

std::string DecodeHelper::kill_and_reap() {
  broken_ = true;
  if (pid_ <= 0) return "gone";
  int status = 0;
  pid_t r = ::waitpid(pid_, &status, WNOHANG);
  const bool ended_by_itself = r == pid_;
  if (!ended_by_itself) {
    ::kill(pid_, SIGKILL);
    while ((r = ::waitpid(pid_, &status, 0)) < 0 && errno == EINTR) {
    }
  }
  const pid_t pid = pid_;
  pid_ = -1;
  if (r != pid) return "lost";
  return fmt::format("pid {} {}{}", pid, describe_wait_status(status), ended_by_itself ? "" : " (by the server)");
}

bool DecodeHelper::usable() {
  if (broken_ || pid_ <= 0) return false;
  int status = 0;
  if (::waitpid(pid_, &status, WNOHANG) == pid_) {  // died while idle: reaped here, nothing to blame
    pid_ = -1;
    broken_ = true;
    return false;
  }
  return true;
}

Status DecodeHelper::serve_read(StorageFile& file, const DecodeFrame& request, uint64_t& bytes_read) {
  if (request.payload_bytes != 0 || request.b > kMaxReadBytes) {
    return make_error(ErrorCode::kProtocol, fmt::format("a read request of {} bytes", request.b));
  }
  if (read_buffer_.size() < request.b) read_buffer_.resize(request.b);
  Result<uint64_t> got = file.read_at(std::span(read_buffer_).first(request.b), request.a);
  DecodeFrame reply;
  reply.type = uint32_t(DecodeFrameType::kReadReply);
  if (!got.ok()) {
    reply.a = 1;
    const std::string& why = got.error().message;
    const size_t n = std::min<size_t>(why.size(), kMaxMessageBytes);
    return channel_.send(reply, std::as_bytes(std::span(why.data(), n)));
  }
  bytes_read += *got;
  reply.b = *got;
  return channel_.send(reply, std::span(read_buffer_).first(*got));
}

Status DecodeHelper::decode(StorageFile& file, const std::filesystem::path& path, uint32_t level, Extent2D expected,
                            std::span<std::byte> out, uint64_t& bytes_read, std::chrono::milliseconds timeout) {
  const uint64_t pixels_bytes = uint64_t{expected.width} * expected.height * 4;
  TS_ASSERT(out.size() >= pixels_bytes, "decode target of %zu bytes for %llu", out.size(),
            static_cast<unsigned long long>(pixels_bytes));
  helper_failed_ = false;
  Result<uint64_t> size = file.size();
  if (!size.ok()) return fail(ErrorCode::kIo, path, level, size.error().message);
  // Everything that is not the file's own fault ends the helper: it is killed, the caller gets an error that
  // names the file, and the pool starts a fresh helper for the next decode.
  // Whether the helper has asked for a byte of this file yet: before that, a timeout may be a helper still
  // starting (loading OpenImageIO's libraries on a loaded machine takes seconds), not the file's doing.
  bool touched_file = false;
  const auto broken = [&](const Error& e) -> Error {
    helper_failed_ = e.code != ErrorCode::kTimeout || touched_file;
    const std::string how = kill_and_reap();
    const ErrorCode code = e.code == ErrorCode::kTimeout ? ErrorCode::kTimeout : ErrorCode::kCorrupt;
    return fail(code, path, level, fmt::format("the decode helper failed ({}): {}", e.message, how));
  };
  const std::string name = path.string();
  if (name.size() > kMaxPathBytes) return fail(ErrorCode::kInvalidArgument, path, level, "path too long");
  DecodeFrame request;
  request.type = uint32_t(DecodeFrameType::kDecode);
  request.a = level;
  request.b = (uint64_t{expected.width} << 32) | expected.height;
  request.c = *size;
  if (Status s = channel_.send(request, std::as_bytes(std::span(name.data(), name.size()))); !s.ok()) {
    // The helper was gone before it got the path (killed from outside while idle): ended like any broken
    // helper, but not counted against this file.
    Error e = broken(s.error());
    helper_failed_ = false;
    return e;
  }
  for (;;) {
    Result<DecodeFrame> frame = channel_.receive_header(timeout);
    if (!frame.ok()) return broken(frame.error());
    if (frame->type == uint32_t(DecodeFrameType::kRead)) {
      touched_file = true;
      if (Status s = serve_read(file, *frame, bytes_read); !s.ok()) return broken(s.error());
      continue;
    }
    if (frame->type != uint32_t(DecodeFrameType::kResult)) {
      return broken(make_error(ErrorCode::kProtocol, fmt::format("an unexpected frame of type {}", frame->type)));
    }
    if (frame->a == 0) {
      if (frame->payload_bytes != pixels_bytes) {
        return broken(make_error(ErrorCode::kProtocol, fmt::format("{} bytes of pixels for {}x{}", frame->payload_bytes,
                                                                   expected.width, expected.height)));
      }
      if (Status s = channel_.receive_payload(out.first(pixels_bytes), timeout); !s.ok()) return broken(s.error());
      return ok_status();
    }
    if (frame->payload_bytes > kMaxMessageBytes || frame->a > uint64_t(ErrorCode::kResourceExhausted) + 1) {
      return broken(make_error(ErrorCode::kProtocol, "a malformed error result"));
    }
    Result<std::string> why = channel_.receive_text(frame->payload_bytes, timeout);
    if (!why.ok()) return broken(why.error());
    // The helper's message already names the path.
    return make_error(static_cast<ErrorCode>(frame->a - 1), std::move(why).value());
  }
}

}  // namespace texstream::server
