#pragma once
// The pipe between the server and its decode helper (texstream-decode, decode/main.cpp): OpenImageIO runs in
// that process so that the server neither links it (~121 MB of resident libraries) nor dies with it.
//
// One stream socket, framed messages, strictly request/reply, one decode at a time per helper:
//   server → helper  kDecode    a = level, b = width << 32 | height, c = file size; payload = the file's path
//   helper → server  kRead      a = offset, b = bytes (≤ kMaxReadBytes): the server reads them through its
//                               Storage (counted, rate-limited, fault-injectable) and answers
//   server → helper  kReadReply a = 0 ok / 1 failed, b = bytes read; payload = those bytes, or the error text
//   helper → server  kResult    a = 0 ok / 1 + ErrorCode; payload = width*height*4 RGBA8 bytes, or the error
// Every header is checked by its reader (magic, type, payload bound). Both ends belong to one build, so the
// frame is native-endian and unversioned. Writes use MSG_NOSIGNAL: a dead peer is an error, never SIGPIPE.
#include <chrono>
#include <cstdint>
#include <span>
#include <string>

#include "texstream/common/result.hpp"

namespace texstream::server {

enum class DecodeFrameType : uint32_t { kDecode = 1, kRead = 2, kReadReply = 3, kResult = 4 };

struct DecodeFrame {
  static constexpr uint32_t kMagic = 0x48445354;  // "TSDH"
  uint32_t magic = kMagic;
  uint32_t type = 0;
  uint64_t a = 0;
  uint64_t b = 0;
  uint64_t c = 0;
  uint64_t payload_bytes = 0;
};
static_assert(sizeof(DecodeFrame) == 40);

// Bounds a reader enforces before it reads a payload: a read request is one OpenImageIO read (tiles, strips,
// headers), a path is a path, an error is a sentence; pixels are bounded by the staging slot the caller has.
inline constexpr uint64_t kMaxReadBytes = 16ull << 20;
inline constexpr uint64_t kMaxPathBytes = 4096;
inline constexpr uint64_t kMaxMessageBytes = 64ull << 10;

// A connected stream socket end. Not thread-safe (one decode at a time uses it). Errors: kPeerDead (EOF or
// a reset: the other process is gone), kTimeout, kProtocol (a bad header), kIo.
class DecodeChannel {
 public:
  DecodeChannel() = default;
  explicit DecodeChannel(int fd) : fd_(fd) {}
  ~DecodeChannel();
  DecodeChannel(DecodeChannel&& other) noexcept;
  DecodeChannel& operator=(DecodeChannel&& other) noexcept;
  DecodeChannel(const DecodeChannel&) = delete;
  DecodeChannel& operator=(const DecodeChannel&) = delete;

  int fd() const { return fd_; }
  // Sends the header (payload_bytes set from `payload`) and the payload.
  Status send(DecodeFrame frame, std::span<const std::byte> payload = {});
  // Receives a header of the expected type(s); `timeout` < 0 waits forever. The payload is not read.
  Result<DecodeFrame> receive_header(std::chrono::milliseconds timeout);
  // Reads exactly `out.size()` payload bytes.
  Status receive_payload(std::span<std::byte> out, std::chrono::milliseconds timeout);
  // Reads a text payload of `bytes` (≤ kMaxMessageBytes, checked by the caller).
  Result<std::string> receive_text(uint64_t bytes, std::chrono::milliseconds timeout);

 private:
  Status read_exact(std::byte* out, size_t n, std::chrono::milliseconds timeout);
  int fd_ = -1;
};

}  // namespace texstream::server
