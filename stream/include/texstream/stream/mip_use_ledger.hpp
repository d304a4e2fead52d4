#pragma once
// Which streamed mips the view ever used (issue 25, "skip what is not needed"; docs/design/stream_metrics.md).
// Mirrors the cache's residency from its events (the same TextureEvents TextureStates hears) and, once a
// frame, the latest visibility list: a resident mip is *displayed* in a frame when its texture is in the list
// and it is a level the texture is sampled at, floor(d) or, for a fractional d, ceil(d) too (trilinear reads
// both), with d = the wanted level clamped to the resident run [finest, coarsest]. A mip's bytes are *wasted*
// when it leaves the cache (evicted, replaced by a second upload of the same level, or still resident at
// finish()) without ever having been displayed while resident.
//
// Its residency also gives the frame's weighted mip deficit (mip_deficit.hpp), so both measures see exactly
// what the shader samples: the run of resident levels ending at the coarsest, as TextureCache::publish.
//
// Cost: apply() is O(events), observe() O(list), finish() O(entries). Memory: a 12-byte entry in an
// open-addressing table (at most half full, never shrinking) per texture with a resident mip, none for the others
// (docs/design/host_memory.md). Single-threaded: the frame loop alone calls it.
#include <cstdint>
#include <span>
#include <vector>

#include "texstream/common/ids.hpp"
#include "texstream/common/open_table.hpp"
#include "texstream/protocol/completion_check.hpp"
#include "texstream/stream/mip_deficit.hpp"
#include "texstream/stream/texture_states.hpp"
#include "texstream/stream/texture_table.hpp"

namespace texstream::stream {

class MipUseLedger {
 public:
  // `shapes`: the scene's texture table, indexed by texture id (a mip's bytes are mip_bytes of its shape).
  explicit MipUseLedger(TextureTable shapes);

  // The cache's events, oldest first: kCommitted makes the mip resident and counts its bytes as uploaded,
  // kInvalidated takes every resident mip of the texture out. Other kinds and unknown textures change nothing.
  void apply(std::span<const TextureEvent> events);
  // The weighted mip deficit of `list` against what is resident now; marks the mips the list samples now as
  // displayed.
  double observe(std::span<const StreamCandidate> list);
  // The run ends: every mip still resident leaves (wasted if never displayed). Residency is empty after it.
  void finish();

  ResidentLevels levels(TextureId texture) const;  // nothing resident for an unknown texture
  uint64_t bytes_uploaded() const { return bytes_uploaded_; }
  uint64_t bytes_wasted() const { return bytes_wasted_; }  // of mips that have left so far
  // bytes_wasted() / bytes_uploaded(); NaN before any upload.
  double wasted_fraction() const;

  // Textures with a resident mip: the entries held (none for the others).
  size_t tracked() const { return uses_.size(); }

 private:
  static constexpr uint32_t kNoTexture = 0xffffffffu;  // an empty slot: ids are below the table's size
  // A texture with a resident mip; erased when its last one leaves.
  struct Use {
    uint32_t key = kNoTexture;
    uint32_t resident = 0;   // bit L: mip L resident (as TextureCache's mask)
    uint32_t displayed = 0;  // bit L: the resident copy of mip L has been displayed
  };
  struct UseUsed {
    bool operator()(const Use& u) const { return u.key != kNoTexture; }
  };
  static_assert(sizeof(Use) == 12);  // the entry size the header comment and host_memory.md state
  // Mips in `leaving` (a subset of u.resident) leave the cache; the caller erases `u` once nothing is resident.
  void leave(Use& u, uint32_t leaving);
  // leave(), then the entry goes if nothing is resident any more (invalidates pointers to entries).
  void leave_and_settle(Use* u, uint32_t leaving);

  TextureTable shapes_;  // shared with the other users of the scene's table
  OpenTable<Use, UseUsed, IdHash> uses_;
  uint64_t bytes_uploaded_ = 0;
  uint64_t bytes_wasted_ = 0;
};

}  // namespace texstream::stream
