#pragma once
// The shared segment's fixed layout, computed by us (never by a managed allocator):
//
//   [0, 4096)           SegmentHeader   written once by the renderer before `ready` is set, then read-only
//   [4096, 4160)        RendererBlock   written by the renderer only
//   [4160, 4288)        ServerBlock     written by the server only
//   request ring        RingControl + RequestRecord[request_capacity]        (renderer produces)
//   completion ring     RingControl + CompletionRecord[completion_capacity]  (server produces)
//   staging slots       slot_count × slot_bytes, each 4 KiB aligned; a slot's owner is whoever the rings
//                       last handed it to (server at start, renderer after a kOk completion, server again
//                       after a kReleaseSlot request)
#include <cstddef>
#include <cstdint>

#include "texstream/protocol/records.hpp"
#include "texstream/protocol/shm_atomic.hpp"
#include "texstream/protocol/spsc_ring.hpp"

namespace texstream {

inline constexpr uint64_t kSegmentMagic = 0x314d525453584554ull;  // "TEXSTRM1" read little-endian
// 2: ServerBlock.loading; 3: the header's texture table; 4: the completion bell, ServerBlock.syscalls;
// 5: RequestKind::kLoadPage (page x, y in the request; request_kind, page x, y in the completion)
inline constexpr uint32_t kLayoutVersion = 5;
inline constexpr uint64_t kSegmentHeaderBytes = 4096;
inline constexpr uint64_t kSlotAlignment = 4096;
inline constexpr uint32_t kCompilerIdBytes = 64;

struct SegmentHeader {
  uint64_t magic;
  uint32_t layout_version;
  uint32_t header_bytes;             // sizeof(SegmentHeader)
  uint32_t boost_version;            // BOOST_VERSION of the creator
  uint32_t request_record_bytes;     // sizeof(RequestRecord)
  uint32_t completion_record_bytes;  // sizeof(CompletionRecord)
  uint32_t reserved0;
  char compiler[kCompilerIdBytes];  // __VERSION__ of the creator, NUL-padded
  uint64_t segment_bytes;
  uint32_t request_capacity;     // records, power of two
  uint32_t completion_capacity;  // records, power of two
  uint32_t slot_count;
  uint32_t reserved1;
  uint64_t slot_bytes;  // multiple of kSlotAlignment
  uint64_t request_ring_offset;
  uint64_t completion_ring_offset;
  uint64_t slots_offset;
  uint64_t epoch;  // random per creation and per reset after a server death
  // The renderer's texture table (texture_table_step over every texture; 0: not stated, nothing checked): a
  // server whose scene differs refuses the segment.
  uint64_t texture_count;
  uint64_t texture_table_fingerprint;
  uint64_t reserved2[6];
};
static_assert(std::is_trivially_copyable_v<SegmentHeader> && std::is_standard_layout_v<SegmentHeader>);
static_assert(sizeof(SegmentHeader) == 224);
static_assert(offsetof(SegmentHeader, compiler) == 32);
static_assert(offsetof(SegmentHeader, segment_bytes) == 96);
static_assert(offsetof(SegmentHeader, slot_bytes) == 120);
static_assert(offsetof(SegmentHeader, epoch) == 152);
static_assert(offsetof(SegmentHeader, texture_count) == 160);
static_assert(offsetof(SegmentHeader, texture_table_fingerprint) == 168);

// Written by the renderer only.
struct alignas(64) RendererBlock {
  ShmAtomic<uint32_t> ready;         // 1 once the header and rings are initialised (release-stored last)
  uint32_t pid;                      // set before `ready`
  uint64_t start_time;               // /proc/<pid>/stat start time (clock ticks since boot): pid + this = identity
  ShmAtomic<uint64_t> heartbeat;     // bumped once per frame: progress, not time
  ShmAtomic<uint64_t> generation;    // the newest streaming cycle
  ShmAtomic<uint32_t> doorbell;      // futex word: bumped after pushing requests
  ShmAtomic<uint32_t> waiting;       // 1 while waiting on ServerBlock::completion_bell (the server then wakes it)
  ShmAtomic<uint64_t> server_epoch;  // epoch the current server was spawned for
  uint64_t reserved1[2];
};
static_assert(sizeof(RendererBlock) == 64);
static_assert(offsetof(RendererBlock, heartbeat) == 16);
static_assert(offsetof(RendererBlock, doorbell) == 32);
static_assert(offsetof(RendererBlock, waiting) == 36);

// Load workers whose current texture the ServerBlock records (ServerBlock::loading): the default server
// runs 2 (config.hpp), the words fill the block's spare 32 bytes.
inline constexpr uint32_t kLoadingWords = 8;

// Written by the server only.
struct alignas(64) ServerBlock {
  ShmAtomic<uint32_t> attached;  // 1 while a server serves this segment
  ShmAtomic<uint32_t> pid;
  ShmAtomic<uint64_t> start_time;
  ShmAtomic<uint64_t> heartbeat;  // bumped by the server loop each iteration: progress, not time
  ShmAtomic<uint32_t> sleeping;   // 1 while waiting on the doorbell futex (the renderer then wakes it)
  // The pid of a standalone server that refused this segment (its scene's texture table differs from the
  // renderer's, SegmentHeader::texture_table_fingerprint) and waits for the next renderer instead. Written
  // by that server, which does not claim the segment (pid stays 0); the renderer ends its run naming it.
  ShmAtomic<uint32_t> refused_by;
  // Statistics (monotonic counters; relaxed stores, read for reports only).
  ShmAtomic<uint64_t> completions;         // completions published
  ShmAtomic<uint64_t> requests_received;   // kLoad records taken off the request ring
  ShmAtomic<uint64_t> requests_cancelled;  // superseded by a newer generation or coalesced away
  ShmAtomic<uint64_t> ram_cache_hits;      // mips served from the RAM cache
  ShmAtomic<uint64_t> ram_cache_misses;    // mips read from storage
  ShmAtomic<uint64_t> bytes_read;          // bytes read from storage (exact mip reads + headers)
  // Crash attribution (issue 9): loading[i] = texture id + 1 while load worker i works on that texture, 0
  // while idle (relaxed stores; workers beyond kLoadingWords are not recorded). Read by the renderer only
  // after the server died by a crash signal, before it resets the block: a texture being loaded during two
  // crashes is quarantined (stream_client.hpp).
  ShmAtomic<uint32_t> loading[kLoadingWords];
  ShmAtomic<uint64_t> syscalls;         // kernel crossings of the dispatcher and the workers (statistic)
  ShmAtomic<uint32_t> completion_bell;  // futex word: bumped after publishing completions (doorbell.hpp)
  uint32_t reserved1;
};
static_assert(sizeof(ServerBlock) == 128);
static_assert(offsetof(ServerBlock, heartbeat) == 16);
static_assert(offsetof(ServerBlock, completions) == 32);
static_assert(offsetof(ServerBlock, loading) == 80);
static_assert(offsetof(ServerBlock, syscalls) == 112);
static_assert(offsetof(ServerBlock, completion_bell) == 120);

struct SegmentParams {
  uint32_t request_capacity = 1024;
  uint32_t completion_capacity = 1024;
  uint32_t slot_count = 64;
  uint64_t slot_bytes = 1u << 20;
  uint64_t texture_count = 0;  // the renderer's texture table (SegmentHeader); 0, 0: not stated
  uint64_t texture_table_fingerprint = 0;
};

struct SegmentLayout {
  uint64_t renderer_block_offset;
  uint64_t server_block_offset;
  uint64_t request_ring_offset;     // RingControl, then records
  uint64_t completion_ring_offset;  // RingControl, then records
  uint64_t slots_offset;
  uint64_t slot_bytes;
  uint64_t total_bytes;
};

constexpr uint64_t align_up(uint64_t v, uint64_t a) { return (v + a - 1) / a * a; }

// Pure arithmetic; the caller has validated params (power-of-two capacities, bounded sizes).
constexpr SegmentLayout compute_layout(const SegmentParams& p) {
  SegmentLayout l{};
  l.renderer_block_offset = kSegmentHeaderBytes;
  l.server_block_offset = l.renderer_block_offset + sizeof(RendererBlock);
  l.request_ring_offset = align_up(l.server_block_offset + sizeof(ServerBlock), 128);
  l.completion_ring_offset =
      align_up(l.request_ring_offset + sizeof(RingControl) + uint64_t{p.request_capacity} * sizeof(RequestRecord), 128);
  l.slots_offset = align_up(
      l.completion_ring_offset + sizeof(RingControl) + uint64_t{p.completion_capacity} * sizeof(CompletionRecord),
      kSlotAlignment);
  l.slot_bytes = align_up(p.slot_bytes, kSlotAlignment);
  l.total_bytes = l.slots_offset + uint64_t{p.slot_count} * l.slot_bytes;
  return l;
}

// Bounds on what a header may claim: a hostile header must not make us map or index absurd sizes.
inline constexpr uint32_t kMaxRingCapacity = 1u << 16;
inline constexpr uint32_t kMaxSlotCount = 1u << 14;
inline constexpr uint64_t kMaxSlotBytes = 64ull << 20;

}  // namespace texstream
