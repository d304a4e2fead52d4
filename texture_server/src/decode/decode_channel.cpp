#include "texstream/server/decode/decode_channel.hpp"

#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <utility>

namespace texstream::server {

DecodeChannel::~DecodeChannel() {
  if (fd_ >= 0) ::close(fd_);
}

DecodeChannel::DecodeChannel(DecodeChannel&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}

DecodeChannel& DecodeChannel::operator=(DecodeChannel&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = std::exchange(other.fd_, -1);
  }
  return *this;
}

Status DecodeChannel::send(DecodeFrame frame, std::span<const std::byte> payload) {
  frame.magic = DecodeFrame::kMagic;
  frame.payload_bytes = payload.size();
  const auto write_all = [this](const std::byte* p, size_t n) -> Status {
    while (n > 0) {
      const ssize_t w = ::send(fd_, p, n, MSG_NOSIGNAL);
      if (w < 0) {
        if (errno == EINTR) continue;
        if (errno == EPIPE || errno == ECONNRESET)
          return make_error(ErrorCode::kPeerDead, "the peer closed the channel");
        return make_error(ErrorCode::kIo, std::string("send: ") + std::strerror(errno));
      }
      p += w;
      n -= static_cast<size_t>(w);
    }
    return ok_status();
  };
  TS_TRY(write_all(reinterpret_cast<const std::byte*>(&frame), sizeof(frame)));
  return write_all(payload.data(), payload.size());
}

Status DecodeChannel::read_exact(std::byte* out, size_t n, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (n > 0) {
    if (timeout.count() >= 0) {
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      pollfd p{fd_, POLLIN, 0};
      const int r = ::poll(&p, 1, static_cast<int>(std::max<int64_t>(0, left.count())));
      if (r < 0 && errno == EINTR) continue;
      if (r < 0) return make_error(ErrorCode::kIo, std::string("poll: ") + std::strerror(errno));
      if (r == 0) return make_error(ErrorCode::kTimeout, "no answer within " + std::to_string(timeout.count()) + " ms");
    }
    const ssize_t got = ::recv(fd_, out, n, 0);
    if (got < 0) {
      if (errno == EINTR) continue;
      if (errno == ECONNRESET) return make_error(ErrorCode::kPeerDead, "the peer closed the channel");
      return make_error(ErrorCode::kIo, std::string("recv: ") + std::strerror(errno));
    }
    if (got == 0) return make_error(ErrorCode::kPeerDead, "the peer closed the channel");
    out += got;
    n -= static_cast<size_t>(got);
  }
  return ok_status();
}

Result<DecodeFrame> DecodeChannel::receive_header(std::chrono::milliseconds timeout) {
  DecodeFrame f;
  TS_TRY(read_exact(reinterpret_cast<std::byte*>(&f), sizeof(f), timeout));
  if (f.magic != DecodeFrame::kMagic) return make_error(ErrorCode::kProtocol, "a frame without the magic number");
  if (f.type < uint32_t(DecodeFrameType::kDecode) || f.type > uint32_t(DecodeFrameType::kResult)) {
    return make_error(ErrorCode::kProtocol, "a frame of unknown type " + std::to_string(f.type));
  }
  return f;
}

Status DecodeChannel::receive_payload(std::span<std::byte> out, std::chrono::milliseconds timeout) {
  return read_exact(out.data(), out.size(), timeout);
}

Result<std::string> DecodeChannel::receive_text(uint64_t bytes, std::chrono::milliseconds timeout) {
  TS_ASSERT(bytes <= kMaxMessageBytes || bytes <= kMaxPathBytes, "unchecked text length %llu",
            static_cast<unsigned long long>(bytes));
  std::string s(bytes, '\0');
  TS_TRY(read_exact(reinterpret_cast<std::byte*>(s.data()), s.size(), timeout));
  return s;
}

}  // namespace texstream::server
