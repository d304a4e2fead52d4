#include "texstream/server/oiio_mip_decoder.hpp"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <fmt/format.h>

#include <atomic>
#include <string>
#include <vector>

#include "texstream/server/texel_conversion.hpp"

namespace texstream::server {

namespace {

// Bound on channels we convert: a hostile header must not make us allocate w*h*2^31 floats.
constexpr int kMaxChannels = 64;

// OpenImageIO reads through this instead of opening the path itself.
class StorageProxy final : public OIIO::Filesystem::IOProxy {
 public:
  StorageProxy(StorageFile& file, const std::string& name, uint64_t size)
      : IOProxy(name, Read), file_(file), size_(size) {}
  const char* proxytype() const override { return "texstream-storage"; }
  size_t read(void* buf, size_t size) override {
    const size_t got = pread(buf, size, m_pos);
    m_pos += static_cast<int64_t>(got);
    return got;
  }
  size_t pread(void* buf, size_t size, int64_t offset) override {
    if (offset < 0) return 0;
    Result<uint64_t> got = file_.read_at({static_cast<std::byte*>(buf), size}, static_cast<uint64_t>(offset));
    if (!got.ok()) {
      io_failed_.store(true, std::memory_order_relaxed);  // relaxed: read after the ImageInput is done
      error(got.error().message);
      return 0;
    }
    bytes_read_.fetch_add(*got, std::memory_order_relaxed);  // relaxed: a counter read after the decode
    return static_cast<size_t>(*got);
  }
  size_t size() const override { return static_cast<size_t>(size_); }
  size_t write(const void*, size_t) override { return 0; }
  size_t pwrite(const void*, size_t, int64_t) override { return 0; }

  uint64_t bytes_read() const { return bytes_read_.load(std::memory_order_relaxed); }
  bool io_failed() const { return io_failed_.load(std::memory_order_relaxed); }

 private:
  StorageFile& file_;
  uint64_t size_;
  // OpenImageIO may call pread from its own threads for some formats; keep the counters atomic.
  std::atomic<uint64_t> bytes_read_{0};
  std::atomic<bool> io_failed_{false};
};

Error fail(ErrorCode code, const std::filesystem::path& path, const std::string& why) {
  // fmt rather than operator+: GCC 12 -O3 warns falsely (-Wrestrict) on some std::string concatenations.
  return make_error(code, fmt::format("'{}': {}", path.string(), why));
}

}  // namespace

Status decode_mip_rgba8(StorageFile& file, const std::filesystem::path& path, uint32_t level, Extent2D expected,
                        std::span<std::byte> out, DecodeOutcome& outcome) {
  const uint64_t out_bytes = mip_bytes(TexelFormat::kRgba8, expected);
  TS_ASSERT(out.size() >= out_bytes, "decode target of %zu bytes for %llu", out.size(),
            static_cast<unsigned long long>(out_bytes));
  Result<uint64_t> size = file.size();
  if (!size.ok()) return fail(ErrorCode::kIo, path, size.error().message);
  StorageProxy proxy(file, path.string(), *size);
  // Whatever happens below, the bytes read are reported (read amplification counts failed loads too).
  struct Report {
    StorageProxy& p;
    DecodeOutcome& o;
    ~Report() { o.bytes_read = p.bytes_read(); }
  } report{proxy, outcome};

  std::unique_ptr<OIIO::ImageInput> in = OIIO::ImageInput::open(path.string(), nullptr, &proxy);
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
  if (is_float) {
    channels_linear_float_to_rgba8(reinterpret_cast<const float*>(decoded.data()), channels, pixels, out.data());
  } else {
    channels_u8_to_rgba8(reinterpret_cast<const uint8_t*>(decoded.data()), channels, pixels, out.data());
  }
  return ok_status();
}

}  // namespace texstream::server
