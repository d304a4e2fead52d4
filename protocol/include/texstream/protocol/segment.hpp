#pragma once
// Creating, opening and validating the shared segment. Boost.Interprocess does only what it is safe at:
// naming, creating, sizing and mapping (shared_memory_object + mapped_region). No Boost mutex, condition,
// managed allocator or message_queue anywhere (DESIGN.md: each hangs when a peer dies at the wrong instant).
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "texstream/common/result.hpp"
#include "texstream/protocol/records.hpp"
#include "texstream/protocol/segment_layout.hpp"
#include "texstream/protocol/spsc_ring.hpp"

namespace texstream {

// A mapped segment. Move-only; unmaps on destruction. The creator also removes the name on destruction.
class Segment {
 public:
  // Renderer: create a new segment (fails if the name exists), initialise header, blocks and rings, and
  // publish `ready`. `name` is a POSIX shm name without the leading slash.
  static Result<std::unique_ptr<Segment>> create(const std::string& name, const SegmentParams& params);
  // Server: map an existing segment, wait for nothing: if it is not ready or its header differs from what
  // this build expects, fail at once with a message naming the field that differs.
  static Result<std::unique_ptr<Segment>> open(const std::string& name);
  // Removes the name of a segment whose owner (pid + start time in its RendererBlock) is no longer alive.
  // Returns the number removed. Names must start with `prefix`.
  static int remove_stale(const std::string& prefix);
  // The same for one exact name (a protocol.segment_name chosen by the user): true if it was removed.
  static bool remove_if_stale(const std::string& name);
  // The pid of the live renderer that owns the segment `name`, if there is one (for messages).
  static std::optional<uint32_t> live_owner(const std::string& name);
  static bool remove(const std::string& name);

  ~Segment();
  Segment(const Segment&) = delete;
  Segment& operator=(const Segment&) = delete;

  const std::string& name() const { return name_; }
  const SegmentHeader& header() const { return header_copy_; }  // validated local copy, never re-read
  RendererBlock& renderer_block() { return *renderer_block_; }
  const RendererBlock& renderer_block() const { return *renderer_block_; }
  ServerBlock& server_block() { return *server_block_; }
  const ServerBlock& server_block() const { return *server_block_; }

  // The two rings, one end each: the renderer produces requests and consumes completions, the server the
  // other way round. Each call makes a new end that resumes from the published position: take new ones after
  // reset_after_server_death(). Process memory only; the segment's words are those of the rings.
  SpscRingProducer<RequestRecord> request_producer() {
    return {request_control_, request_records_, header_copy_.request_capacity};
  }
  SpscRingConsumer<RequestRecord> request_consumer() {
    return {request_control_, request_records_, header_copy_.request_capacity};
  }
  SpscRingProducer<CompletionRecord> completion_producer() {
    return {completion_control_, completion_records_, header_copy_.completion_capacity};
  }
  SpscRingConsumer<CompletionRecord> completion_consumer() {
    return {completion_control_, completion_records_, header_copy_.completion_capacity};
  }
  // The rings' raw words, for tests that corrupt a position or a record on purpose.
  RingControl* request_control() { return request_control_; }
  const RingControl* request_control() const { return request_control_; }
  RequestRecord* request_records() { return request_records_; }
  RingControl* completion_control() { return completion_control_; }
  const RingControl* completion_control() const { return completion_control_; }
  CompletionRecord* completion_records() { return completion_records_; }

  uint32_t slot_count() const { return header_copy_.slot_count; }
  uint64_t slot_bytes() const { return header_copy_.slot_bytes; }
  // Bounds-checked by construction: index < slot_count is asserted (callers validate untrusted indices first).
  std::span<std::byte> slot(uint32_t index);

  // Renderer only, and only after the server process has been reaped: zero the rings and server block so a
  // new server starts clean, and change the epoch. The dead server was the sole writer of its words.
  void reset_after_server_death();

 private:
  Segment() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::string name_;
  bool owner_ = false;
  SegmentHeader header_copy_{};
  std::byte* base_ = nullptr;
  RendererBlock* renderer_block_ = nullptr;
  ServerBlock* server_block_ = nullptr;
  RingControl* request_control_ = nullptr;
  RequestRecord* request_records_ = nullptr;
  RingControl* completion_control_ = nullptr;
  CompletionRecord* completion_records_ = nullptr;
};

// Checks a header copy against this build: magic, version, record sizes, Boost version, compiler, and that
// the claimed sizes and offsets are consistent and fit in `mapped_bytes`. The message names the field.
Status validate_header(const SegmentHeader& h, uint64_t mapped_bytes);

// Fills a header for `params` as this build would write it.
SegmentHeader make_header(const SegmentParams& params, uint64_t epoch);

}  // namespace texstream
