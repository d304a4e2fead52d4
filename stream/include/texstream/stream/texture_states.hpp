#pragma once
// Per-texture streaming states of seed 000 (Algorithm 1, LoadTextures; §3.5): Initial → Active → Final, one
// mip per texture per streaming cycle, coarsest first, refined only while the bias-modified sampled level
// asks for more than is displayed, and the cycle stops once the load size s is exceeded.
//
// Pure and deterministic: no clock, no I/O, no Vulkan. The caller feeds it one cycle's sorted visibility
// list and hands each chosen mip to a `send` function (in the renderer: StreamClient::try_request); events
// from the streaming side (a mip uploaded, a load failed, a cache layer evicted) come back through
// on_committed / on_failed / on_rejected / invalidate, or as a list of TextureEvents through apply(). Single-
// threaded: one owner calls everything (in the renderer the frame loop, which hands over the cache's events).
//
// How the paper's synchronous loop maps onto an asynchronous server:
//   * The paper's `texture.mipLevel` (the displayed level) is `resident`: the finest level the renderer
//     has uploaded, updated only by on_committed().
//   * A request in flight is `pending`. With `levels_in_flight` = 1 (the seed's Algorithm 1) a texture with a
//     pending request is skipped ("only one request per texture in flight"). With more, a texture may have up
//     to that many levels in flight, each the next finer one after what is resident or pending (its chain is
//     pipelined instead of one level per round trip: docs/design/pipelined_levels.md). Levels are kept as
//     masks, so an answer that arrives ahead of a coarser one, or a coarser one that failed, is a hole that
//     the next cycle asks for again; `resident` is the run of resident levels that ends at the coarsest one,
//     the range the renderer's shader samples.
//   * The state changes that Algorithm 1 makes when it decides to load happen when the request is sent;
//     a failed load rolls them back (Initial request failed → Initial; base-mip request failed → Active).
//   * The load-size test `if loadedBatchSize > s then break` runs before each load, exactly as in
//     Algorithm 1, so the mip that first pushes the batch over s is still loaded; unlike the listing, the
//     test comes before the state change, so the texture that hits the limit keeps its state.
//
// Memory: a texture in the default state (Initial, nothing resident or pending, not broken, no counted failure)
// has no entry; one that is not has a 16-byte entry in an open-addressing table at most half full. So a
// texture not in view costs nothing (docs/design/host_memory.md); the table is as large as the peak count of
// resident, pending, broken or failed textures needs (it never shrinks).
#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <unordered_set>
#include <vector>

#include "texstream/common/ids.hpp"
#include "texstream/common/open_table.hpp"
#include "texstream/protocol/completion_check.hpp"
#include "texstream/protocol/records.hpp"
#include "texstream/stream/texture_table.hpp"

namespace texstream::stream {

enum class TexturePhase : uint8_t {
  kInitial,  // nothing loaded or asked for: the next cycle that sees it requests its initial mip
  kActive,   // a mip is resident or pending and finer ones may follow
  kFinal,    // the base mip (level 0) was requested or is resident: nothing left to stream
};

const char* to_string(TexturePhase phase);

// One entry of a cycle's compacted visibility list (seed 000 §3.3: mip level, weight, mesh id → texture).
struct StreamCandidate {
  TextureId texture;
  float desired_mip;  // the paper's mipLevelSampled: the level the GPU metadata asks for (may be fractional)
  float weight;       // Eq. 1 mesh weight; the list is sorted by it, descending, and it becomes the priority
};

struct MipRequest {
  TextureId texture;
  MipLevel mip;
  float priority;
  uint64_t bytes;  // the mip's payload size, counted against the load size s
};

// What `send` answers for one request.
enum class SendResult : uint8_t {
  kSent,  // on its way: the state machine records it as pending
  kSkip,  // not now for this texture only (e.g. that mip is still in flight from before an eviction)
  kStop,  // no room at all (ring full, in-flight limit): end this cycle
};

struct TextureStateView {
  TexturePhase phase;
  std::optional<uint32_t> resident;  // finest level of the resident run that ends at the coarsest, if any
  std::optional<uint32_t> pending;   // finest level in flight, if any
  uint32_t pending_levels = 0;       // levels in flight (at most levels_in_flight)
  bool broken;
  uint32_t failures;  // consecutive counted failures (see kMaxCountedFailures)
};

struct TextureStateCounts {
  uint64_t initial = 0;
  uint64_t active = 0;
  uint64_t final = 0;
  uint64_t broken = 0;
  uint64_t pending = 0;
};

struct CycleResult {
  std::vector<MipRequest> sent;
  uint64_t bytes = 0;  // sum of sent[i].bytes
  bool stopped_by_load_size = false;
  bool stopped_by_sender = false;
  bool stopped_by_count = false;  // max_requests reached
  uint64_t unknown_textures = 0;  // candidates whose id is not in the texture table (ignored)
};

// The first mip Algorithm 1 loads ("We use the 4x4 mipmap", mipLevelMax): the coarsest level whose larger
// side is still at least 4 texels, i.e. floor(log2(max(w, h))) - 2, so its larger side is 4..7 texels (4
// exactly for power-of-two sizes; a BC1 4x4 level is one block). A texture whose larger side is below 4 has
// no such level: its initial mip is its base level 0. Clamped to the texture's last stored level.
uint32_t initial_mip_level(const TextureShape& shape);

// What the streaming side learnt about one texture, in the order it happened: the renderer's texture cache
// collects them (TextureCache::take_events) and the frame loop hands them to TextureStates::apply, so the
// states are fed from one side only.
struct TextureEvent {
  enum class Kind : uint8_t {
    kCommitted,    // on_committed(texture, mip)
    kFailed,       // on_failed(texture, mip, status)
    kRejected,     // on_rejected(texture, mip)
    kInvalidated,  // invalidate(texture)
    kNoRoom,       // on_no_room(texture, mip)
    kTrimmed,      // on_trimmed(texture, mip): levels finer than `mip` were dropped
  };
  Kind kind;
  TextureId texture;
  MipLevel mip{};
  CompletionStatus status = CompletionStatus::kOk;
};

class TextureStates {
 public:
  // Failures that are not the texture's fault (unfilled, cancelled, timed out: the server was busy, the
  // request was superseded or the server restarted) are retried forever. Failures that may be the file's
  // (i/o error, a payload the renderer rejected) are retried too, but this many in a row mark the texture
  // broken for the session, so a bad file cannot cost a request every cycle forever.
  static constexpr uint32_t kMaxCountedFailures = 4;

  // `shapes` is the scene's texture table, indexed by texture id. A shape with no mips is broken from start.
  // `levels_in_flight` (config stream.levels_in_flight, >= 1): most levels of one texture requested at once;
  // 1 is the seed's Algorithm 1.
  explicit TextureStates(TextureTable shapes, uint32_t levels_in_flight = 1);

  using Sender = std::function<SendResult(const MipRequest&)>;

  // One streaming cycle of Algorithm 1 (LoadTextures) over `candidates` in the given order (the caller
  // sorts by descending weight), with load size `load_bytes` (s) and mip bias `bias` (b >= 0). Every mip
  // chosen is passed to `send`, in order, and what it accepts is returned. `max_requests` (config
  // stream.max_mips_per_cycle) caps the mips sent in one cycle on top of s. With levels_in_flight > 1 the
  // cycle makes up to that many passes: the first gives each texture its next level (Algorithm 1 exactly),
  // each further pass one more level to the textures the pass before sent one, at priority weight / 4^pass
  // (a level finer costs four times the bytes), so every texture's next level goes before anyone's deeper ones.
  CycleResult run_cycle(std::span<const StreamCandidate> candidates, uint64_t load_bytes, float bias,
                        const Sender& send, size_t max_requests = SIZE_MAX);

  // The renderer has uploaded `mip` of `texture` and may sample it. Returns false (and changes nothing)
  // when that mip is not a pending one: a late answer to a request from before an invalidate().
  bool on_committed(TextureId texture, MipLevel mip);
  // The load of `mip` failed with `status` (kCancelled also for requests lost with a dead server). Rolls
  // the pending state back; kNotFound and kCorrupt mark the texture broken. Returns false when not pending.
  bool on_failed(TextureId texture, MipLevel mip, CompletionStatus status);
  // The payload of `mip` arrived but was rejected (checksum or size mismatch). Rolls back and counts.
  bool on_rejected(TextureId texture, MipLevel mip);
  // The cache had no room for the pending mip (everything it could evict is in use this cycle): rolled back
  // like a rejection, but not the texture's fault, so it is asked again later and never marked broken.
  bool on_no_room(TextureId texture, MipLevel mip);
  // The cache dropped the resident levels finer than `finest` (finer than the view wants, to make room):
  // `finest` is now the finest resident level, refined again by Algorithm 1 if the view comes closer.
  void on_trimmed(TextureId texture, MipLevel finest);
  // The cache evicted the texture (seed 000 §3.6: its layer was reused): back to Initial, nothing resident,
  // nothing pending (a late answer to the old request is then refused by on_committed). Broken stays broken.
  void invalidate(TextureId texture);
  // Each event in order, as the call its kind names.
  void apply(std::span<const TextureEvent> events);

  size_t size() const { return shapes_.size(); }  // textures in the table
  uint32_t levels_in_flight() const { return levels_in_flight_; }
  bool contains(TextureId texture) const { return texture.value < shapes_.size(); }
  TextureStateView view(TextureId texture) const;  // contract: contains(texture)
  TextureStateCounts counts() const;               // O(entries)
  // Textures whose state is not the default one: the entries held (a texture not in view has none).
  size_t tracked() const { return states_.size(); }

 private:
  static constexpr uint8_t kNone = 0xff;  // no level: levels are below 32 (a 32-bit extent has at most 32)
  struct State {
    uint32_t resident = 0;  // bit m: level m is uploaded (as the cache's residency mask)
    uint32_t pending = 0;   // bit m: level m is in flight
    bool broken = false;
    uint8_t failures = 0;
    // The state of a texture with no entry (unless its shape has no mips: broken, derived from the shape).
    bool is_default() const { return resident == 0 && pending == 0 && !broken && failures == 0; }
  };
  // Where the run of resident-or-pending levels that starts at the coarsest one ends (its finest level), or
  // kNone when nothing is resident or pending: Algorithm 1's `texture.mipLevel` once the pending arrive.
  static uint32_t frontier(const State& s);
  // Phase of a state: Initial with nothing resident or pending, Final once the frontier is the base level.
  static TexturePhase phase_of(const State& s);
  static constexpr uint32_t kNoTexture = 0xffffffffu;  // an empty slot: ids are below the table's size
  struct Entry {
    uint32_t key = kNoTexture;
    State state;
  };
  struct EntryUsed {
    bool operator()(const Entry& e) const { return e.key != kNoTexture; }
  };
  static_assert(sizeof(Entry) == 16);  // the entry size the header comment and host_memory.md state

  // The level Algorithm 1 would load for `texture` in state `s` now, or nullopt.
  std::optional<uint32_t> next_mip(const State& s, uint32_t texture, float desired, float bias) const;
  // The entry of a texture with `mip` pending, or nullptr: an event for `mip` changes only such a texture.
  Entry* pending_entry(TextureId texture, MipLevel mip);
  // Drops `e` if its texture is back in the default state (invalidates pointers to entries).
  void settle(Entry* e);

  TextureTable shapes_;  // shared with the other users of the scene's table
  uint32_t levels_in_flight_ = 1;
  // run_cycle's scratch, kept so that a cycle on the frame thread allocates nothing once warm: the candidates
  // of the pass before and of this one, and the textures the first pass sent a level (levels_in_flight > 1).
  std::vector<uint32_t> pass_scratch_[2];
  std::unordered_set<uint32_t> sent_textures_;
  OpenTable<Entry, EntryUsed, IdHash> states_;
  uint64_t broken_from_start_ = 0;  // shapes with no mips: broken without an entry
};

}  // namespace texstream::stream
