#pragma once
// The MipSinks the stream client copies completions through on their way into the texture cache (itself the
// innermost MipSink): a per-frame budget for taking completions, and commits applied in (texture, mip) order.
// Both only filter or reorder; every byte still lands in the cache's staging ring. Frame thread only.
#include <chrono>
#include <vector>

#include "texstream/stream/stream_client.hpp"

namespace texstream::render {

// Seed 000's load time (Table 2: 16 ms) in the two-process design: file reads run in texstream-server, off
// the frame; what a frame still spends on loading is taking completions (check, copy into staging, checksum,
// queue the copy). Once a frame has spent controller.load_time_ms on that, reserve() answers "no room now":
// the client keeps the completion and offers it first next frame. The first mip of a frame always passes.
class LoadTimeSink final : public stream::MipSink {
 public:
  using Clock = std::chrono::steady_clock;
  LoadTimeSink(stream::MipSink& inner, Clock::time_point deadline) : inner_(inner), deadline_(deadline) {}
  std::span<std::byte> reserve(TextureId texture, MipLevel mip, uint64_t bytes) override;
  void commit(TextureId texture, MipLevel mip, std::span<std::byte> data) override {
    inner_.commit(texture, mip, data);
  }
  void reject(TextureId texture, MipLevel mip, std::span<std::byte> reserved) override {
    inner_.reject(texture, mip, reserved);
  }
  void failed(TextureId texture, MipLevel mip, CompletionStatus status) override {
    inner_.failed(texture, mip, status);
  }
  bool limited() const { return limited_; }
  bool no_room() const { return no_room_; }  // the staging ring was full: the rest waits for the next frame

 private:
  stream::MipSink& inner_;
  Clock::time_point deadline_;
  uint64_t taken_ = 0;
  bool limited_ = false;
  bool no_room_ = false;
};

// Lock-step: commits (which place textures in cache regions) are applied in (texture, mip) order instead of
// the server's completion order, which its worker threads make nondeterministic; otherwise a texture's region,
// and so the last bit of some filtered texels, would differ between two runs of the same path.
class OrderedCommitSink final : public stream::MipSink {
 public:
  explicit OrderedCommitSink(stream::MipSink& inner) : inner_(inner) {}
  std::span<std::byte> reserve(TextureId texture, MipLevel mip, uint64_t bytes) override {
    return inner_.reserve(texture, mip, bytes);
  }
  void commit(TextureId texture, MipLevel mip, std::span<std::byte> data) override {
    pending_.push_back({texture, mip, data});
  }
  void reject(TextureId texture, MipLevel mip, std::span<std::byte> reserved) override {
    inner_.reject(texture, mip, reserved);
  }
  void failed(TextureId texture, MipLevel mip, CompletionStatus status) override {
    inner_.failed(texture, mip, status);
  }
  // Hands the commits held so far to the inner sink, in (texture, mip) order.
  void flush();

 private:
  struct Pending {
    TextureId texture;
    MipLevel mip;
    std::span<std::byte> data;
  };
  stream::MipSink& inner_;
  std::vector<Pending> pending_;
};

}  // namespace texstream::render
