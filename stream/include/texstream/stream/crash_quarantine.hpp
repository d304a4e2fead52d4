#pragma once
// Crash quarantine (issue 9): which texture a dead server is charged to. The server records in
// ServerBlock::loading the texture each load worker is working on. When the server dies by a crash signal
// it raised itself (SIGSEGV, SIGBUS, SIGABRT, SIGFPE, SIGILL: never SIGKILL, which is the watchdog,
// texstream-chaos or the OOM killer), or hangs while serving and is killed for it, the textures in those
// words are charged one death each, read before the segment is reset. A texture charged
// kQuarantineAfterCrashes times is quarantined for the client's life: it is never requested again (every
// request of it fails at once with kCorrupt, as a broken file does, so the texture states leave it on its
// colormap), and its requests lost with the dead server fail with kCorrupt instead of kCancelled. A
// texture that merely shared a crash with a guilty one is charged once and served on.
//
// Single-threaded: the renderer's frame thread (through StreamClient) makes every call.
#include <cstdint>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "texstream/common/ids.hpp"
#include "texstream/protocol/segment_layout.hpp"
#include "texstream/stream/mip_sink.hpp"

namespace texstream::stream {

class CrashQuarantine {
 public:
  // Deaths while a texture was being loaded before it is quarantined (issue 9: "a file that crashed it
  // twice"): one is forgiven, as a texture may share a crash with another one that caused it.
  static constexpr uint32_t kQuarantineAfterCrashes = 2;

  // `texture_count`: the texture table's size; a dead server's words naming ids beyond it are ignored.
  explicit CrashQuarantine(size_t texture_count = 0) : texture_count_(texture_count) {}

  // A server died by signal `signal`: if it is a crash signal (one it raised itself), charges the textures
  // `block` says its workers were loading and returns true. Call before the segment is reset.
  bool charge_crash(int signal, const ServerBlock& block);
  // The same for a server killed because it hung while serving (its heartbeat stalled): a texture whose
  // load blocks the server (a file that blocks every read, a stuck mount) is charged like one that crashes it.
  void charge_hang(const ServerBlock& block);

  bool quarantined(uint32_t texture) const { return quarantined_.count(texture) != 0; }
  bool quarantined(TextureId texture) const { return quarantined(texture.value); }
  // A request of a quarantined texture, refused: failed (kCorrupt) by the next fail_refused(), once.
  void refuse(TextureId texture, MipLevel mip);
  // Fails every request refused since the last call.
  void fail_refused(MipSink& sink);

  uint64_t textures_quarantined() const { return quarantined_.size(); }
  // Texture ids charged with at least one death, and those quarantined, ascending.
  std::vector<uint32_t> charged_ids() const;
  std::vector<uint32_t> quarantined_ids() const;

 private:
  // Charges the textures in ServerBlock::loading with one death described by `how` ("died by signal 11").
  void charge_loading(const ServerBlock& block, const std::string& how);
  static uint64_t key(TextureId texture, MipLevel mip) { return (uint64_t{texture.value} << 32) | mip.value; }

  size_t texture_count_;
  std::unordered_map<uint32_t, uint32_t> charges_;  // texture id → deaths while it was being loaded
  std::unordered_set<uint32_t> quarantined_;        // texture ids
  std::vector<uint64_t> refused_;                   // keys refused since the last fail_refused()
  std::unordered_set<uint64_t> refused_set_;        // the same keys: each failed once per poll
};

}  // namespace texstream::stream
