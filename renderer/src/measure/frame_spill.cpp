#include "texstream/render/measure/frame_spill.hpp"

#include <cerrno>
#include <cstring>
#include <string>

#include "texstream/common/contract.hpp"

namespace texstream::render {

Result<FrameSpill> FrameSpill::create(const std::filesystem::path& file, size_t frame_bytes) {
  FrameSpill s;
  s.f_.reset(std::fopen(file.c_str(), "w+b"));
  if (!s.f_) return make_error(ErrorCode::kIo, file.string() + ": cannot create: " + std::strerror(errno));
  s.file_ = file;
  s.frame_bytes_ = frame_bytes;
  return s;
}

FrameSpill::~FrameSpill() {
  if (!f_) return;  // moved from
  f_.reset();
  std::error_code ec;
  std::filesystem::remove(file_, ec);
}

Status FrameSpill::append(std::span<const std::byte> pixels) {
  TS_ASSERT(pixels.size() == frame_bytes_, "FrameSpill::append: %zu bytes for a %zu-byte frame", pixels.size(),
            frame_bytes_);
  if (std::fseek(f_.get(), 0, SEEK_END) != 0 ||
      std::fwrite(pixels.data(), 1, pixels.size(), f_.get()) != pixels.size()) {
    return make_error(ErrorCode::kIo, file_.string() + ": write of frame " + std::to_string(frames_) +
                                          " failed: " + std::strerror(errno));
  }
  ++frames_;
  return ok_status();
}

Status FrameSpill::read(uint64_t index, std::vector<std::byte>& out) {
  TS_ASSERT(index < frames_, "FrameSpill::read: frame %llu of %llu", static_cast<unsigned long long>(index),
            static_cast<unsigned long long>(frames_));
  out.resize(frame_bytes_);
  if (std::fflush(f_.get()) != 0 || std::fseek(f_.get(), static_cast<long>(index * frame_bytes_), SEEK_SET) != 0 ||
      std::fread(out.data(), 1, out.size(), f_.get()) != out.size()) {
    return make_error(ErrorCode::kIo, file_.string() + ": read of frame " + std::to_string(index) + " failed");
  }
  return ok_status();
}

}  // namespace texstream::render
