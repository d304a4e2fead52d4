// texstream-decode: decodes mips of image files through OpenImageIO for texstream-server, in its own process
// (decode_channel.hpp has the protocol; decode_helper.cpp the server's side). Started by the server with its
// end of a socket pair as --fd N; reads every byte of a file through the server (kRead); exits when the
// channel closes or the server goes away.
//
// What it decodes and how is what the server did in-process before: one level (seek_subimage(0, level) +
// read_image: for a tiled file only that level's tiles), checked against the texture table's extent, into
// RGBA8 (texel_conversion.hpp). OpenImageIO 2.4 returns true from reads of truncated JPEG and TIFF files with
// wrong pixels, so a read succeeds only if it returned true AND has_error() is false AND no read failed.
//
// Test hooks (issue 9's quarantine tests; unset in normal runs, read once at start):
//   TEXSTREAM_DECODE_CRASH_ON=<text>  abort() when asked to decode a path that contains <text>
//   TEXSTREAM_DECODE_HANG_ON=<text>   read the file's first bytes, then stop answering (sleep until killed)
// They stand in for a hostile file that crashes or hangs OpenImageIO, which no fixed file does reliably
// across OpenImageIO versions.
#include <sys/resource.h>
#include <unistd.h>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <fmt/format.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "texstream/common/texel_format.hpp"
#include "texstream/server/decode/decode_channel.hpp"
#include "texstream/server/decode/texel_conversion.hpp"

namespace texstream::server {
namespace {

// Bound on channels we convert: a hostile header must not make us allocate w*h*2^31 floats.
constexpr int kMaxChannels = 64;
// The helper never times out on the server (it only waits for the next request or a read's answer).
constexpr std::chrono::milliseconds kForever{-1};

// OpenImageIO reads through this: each read is a kRead answered by the server from its Storage.
class RemoteProxy final : public OIIO::Filesystem::IOProxy {
 public:
  RemoteProxy(DecodeChannel& channel, const std::string& name, uint64_t size)
      : IOProxy(name, Read), channel_(channel), size_(size) {}
  const char* proxytype() const override { return "texstream-remote"; }
  size_t read(void* buf, size_t size) override {
    const size_t got = pread(buf, size, m_pos);
    m_pos += static_cast<int64_t>(got);
    return got;
  }
  size_t pread(void* buf, size_t size, int64_t offset) override {
    if (offset < 0 || channel_dead_) return 0;
    // OpenImageIO may call pread from its own threads for some formats: one exchange at a time.
    std::lock_guard lock(mutex_);
    size_t done = 0;
    while (done < size) {
      const uint64_t want = std::min<uint64_t>(size - done, kMaxReadBytes);
      DecodeFrame request;
      request.type = uint32_t(DecodeFrameType::kRead);
      request.a = static_cast<uint64_t>(offset) + done;
      request.b = want;
      Result<DecodeFrame> reply = channel_.send(request).ok()
                                      ? channel_.receive_header(kForever)
                                      : Result<DecodeFrame>(make_error(ErrorCode::kPeerDead, ""));
      if (!reply.ok() || reply->type != uint32_t(DecodeFrameType::kReadReply)) {
        channel_dead_ = true;  // the server is gone or confused: main() exits after this decode
        error("the server stopped answering reads");
        io_failed_ = true;
        return done;
      }
      if (reply->a != 0) {
        Result<std::string> why = reply->payload_bytes <= kMaxMessageBytes
                                      ? channel_.receive_text(reply->payload_bytes, kForever)
                                      : Result<std::string>(make_error(ErrorCode::kProtocol, "long error"));
        io_failed_ = true;
        if (!why.ok()) channel_dead_ = true;
        error(why.ok() ? *why : std::string("read failed"));
        return done;
      }
      if (reply->b > want || reply->payload_bytes != reply->b ||
          !channel_.receive_payload({static_cast<std::byte*>(buf) + done, reply->b}, kForever).ok()) {
        channel_dead_ = true;
        io_failed_ = true;
        error("a malformed read reply");
        return done;
      }
      done += reply->b;
      if (reply->b < want) break;  // end of file
    }
    return done;
  }
  size_t size() const override { return static_cast<size_t>(size_); }
  size_t write(const void*, size_t) override { return 0; }
  size_t pwrite(const void*, size_t, int64_t) override { return 0; }

  bool io_failed() const { return io_failed_; }
  bool channel_dead() const { return channel_dead_; }

 private:
  DecodeChannel& channel_;
  uint64_t size_;
  std::mutex mutex_;
  bool io_failed_ = false;
  bool channel_dead_ = false;
};

struct Outcome {
  ErrorCode code = ErrorCode::kCorrupt;
  std::string message;  // empty: success
};

Outcome fail(ErrorCode code, const std::string& path, const std::string& why) {
  return Outcome{code, fmt::format("'{}': {}", path, why)};
}

// Decodes mip `level` of `path` into `out` (expected.width * expected.height * 4 bytes).
Outcome decode(RemoteProxy& proxy, const std::string& path, uint32_t level, Extent2D expected,
               std::vector<std::byte>& out) {
  std::unique_ptr<OIIO::ImageInput> in = OIIO::ImageInput::open(path, nullptr, &proxy);
  if (!in) {
    const ErrorCode code = proxy.io_failed() ? ErrorCode::kIo : ErrorCode::kCorrupt;
    return fail(code, path, fmt::format("OpenImageIO cannot open it: {}", OIIO::geterror()));
  }
  in->threads(1);  // the server's worker pool is the CPU bound (seed 002 §3.3); no hidden OIIO pool threads
  if (!in->seek_subimage(0, static_cast<int>(level))) {
    return fail(ErrorCode::kCorrupt, path, fmt::format("has no mip level {} ({})", level, in->geterror()));
  }
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width != static_cast<int>(expected.width) || spec.height != static_cast<int>(expected.height) ||
      spec.depth > 1) {
    return fail(ErrorCode::kCorrupt, path,
                fmt::format("mip {} is {}x{}, the texture table says {}x{}", level, spec.width, spec.height,
                            expected.width, expected.height));
  }
  if (spec.nchannels < 1 || spec.nchannels > kMaxChannels) {
    return fail(ErrorCode::kCorrupt, path, fmt::format("{} channels", spec.nchannels));
  }
  const uint32_t channels = static_cast<uint32_t>(std::min(spec.nchannels, 4));
  const size_t pixels = size_t{expected.width} * expected.height;
  // Half and float data are linear light (OpenEXR's convention): encode to sRGB. Integer data are read as
  // 8-bit (OpenImageIO rescales 16-bit) and taken as already sRGB-encoded, as image files and maketx keep them.
  const bool is_float = spec.format.is_floating_point();
  const OIIO::TypeDesc type = is_float ? OIIO::TypeDesc::FLOAT : OIIO::TypeDesc::UINT8;
  std::vector<std::byte> decoded(pixels * channels * type.size());
  bool ok = in->read_image(0, static_cast<int>(level), 0, static_cast<int>(channels), type, decoded.data());
  // OIIO 2.4: a truncated TIFF/JPEG read can return true with wrong pixels; has_error() tells.
  ok = ok && !in->has_error() && !proxy.io_failed();
  if (!ok) {
    const ErrorCode code = proxy.io_failed() ? ErrorCode::kIo : ErrorCode::kCorrupt;
    std::string why = in->geterror();
    if (why.empty()) why = proxy.error();
    return fail(code, path, fmt::format("cannot read mip {}: {}", level, why));
  }
  in->close();
  out.resize(pixels * 4);
  if (is_float) {
    channels_linear_float_to_rgba8(reinterpret_cast<const float*>(decoded.data()), channels, pixels, out.data());
  } else {
    channels_u8_to_rgba8(reinterpret_cast<const uint8_t*>(decoded.data()), channels, pixels, out.data());
  }
  return Outcome{};
}

// The test hooks above; empty = off.
struct TestHooks {
  std::string crash_on;
  std::string hang_on;
};

TestHooks read_test_hooks() {
  TestHooks h;
  if (const char* v = std::getenv("TEXSTREAM_DECODE_CRASH_ON"); v != nullptr) h.crash_on = v;
  if (const char* v = std::getenv("TEXSTREAM_DECODE_HANG_ON"); v != nullptr) h.hang_on = v;
  return h;
}

void apply_test_hooks(const TestHooks& hooks, const std::string& path, RemoteProxy& proxy) {
  if (!hooks.crash_on.empty() && path.find(hooks.crash_on) != std::string::npos) {
    const rlimit no_core{0, 0};
    ::setrlimit(RLIMIT_CORE, &no_core);  // a deliberate crash leaves no core file behind in tests
    std::abort();
  }
  if (!hooks.hang_on.empty() && path.find(hooks.hang_on) != std::string::npos) {
    // As OpenImageIO stuck on a hostile header would: the header read first (the server charges a timeout
    // to the file only once the helper has read from it), then nothing.
    char header[16];
    (void)proxy.pread(header, sizeof header, 0);
    for (;;) ::pause();  // the server's timeout kills us (SIGKILL), or the orphan watch in main() ends us
  }
}

int serve(int fd) {
  const TestHooks hooks = read_test_hooks();
  DecodeChannel channel(fd);
  std::vector<std::byte> pixels;
  for (;;) {
    Result<DecodeFrame> request = channel.receive_header(kForever);
    if (!request.ok()) return request.error().code == ErrorCode::kPeerDead ? 0 : 2;  // EOF: the server is done
    if (request->type != uint32_t(DecodeFrameType::kDecode) || request->payload_bytes > kMaxPathBytes) return 2;
    Result<std::string> path = channel.receive_text(request->payload_bytes, kForever);
    if (!path.ok()) return 2;
    const Extent2D expected{static_cast<uint32_t>(request->b >> 32), static_cast<uint32_t>(request->b)};
    // The slot bound the server enforces is far below this; a larger request is a broken server.
    if (uint64_t{expected.width} * expected.height * 4 > (1ull << 32)) return 2;
    RemoteProxy proxy(channel, *path, request->c);
    apply_test_hooks(hooks, *path, proxy);
    const Outcome outcome = decode(proxy, *path, static_cast<uint32_t>(request->a), expected, pixels);
    if (proxy.channel_dead()) return 2;
    DecodeFrame result;
    result.type = uint32_t(DecodeFrameType::kResult);
    Status sent = ok_status();
    if (outcome.message.empty()) {
      sent = channel.send(result, pixels);
    } else {
      result.a = uint64_t(outcome.code) + 1;
      const size_t n = std::min<size_t>(outcome.message.size(), kMaxMessageBytes);
      sent = channel.send(result, std::as_bytes(std::span(outcome.message.data(), n)));
    }
    if (!sent.ok()) return 0;
  }
}

}  // namespace
}  // namespace texstream::server

int main(int argc, char** argv) {
  if (argc != 3 || std::strcmp(argv[1], "--fd") != 0) {
    std::fprintf(stderr, "usage: texstream-decode --fd N (started by texstream-server, not by hand)\n");
    return 2;
  }
  const int fd = std::atoi(argv[2]);
  // Orphaned (the server died while OpenImageIO was busy, so no EOF is read): exit. The channel's EOF covers
  // the idle case; this covers a decode that never returns.
  const pid_t parent = ::getppid();
  std::thread([parent] {
    for (;;) {
      std::this_thread::sleep_for(std::chrono::milliseconds(500));
      if (::getppid() != parent) std::_Exit(0);
    }
  }).detach();
  return texstream::server::serve(fd);
}
