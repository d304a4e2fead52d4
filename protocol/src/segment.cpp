#include "texstream/protocol/segment.hpp"

#include <dirent.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <boost/interprocess/mapped_region.hpp>
#include <boost/interprocess/shared_memory_object.hpp>
#include <boost/version.hpp>
#include <cstring>
#include <new>
#include <random>

#include "texstream/protocol/liveness.hpp"

namespace bip = boost::interprocess;

namespace texstream {

struct Segment::Impl {
  bip::shared_memory_object shm;
  bip::mapped_region region;
};

namespace {

Error header_error(const std::string& field, const std::string& got, const std::string& want) {
  return make_error(ErrorCode::kProtocol,
                    "segment header field '" + field + "' is " + got + ", this build expects " + want);
}

std::string compiler_id() {
#ifdef __VERSION__
  return __VERSION__;
#else
  return "unknown";
#endif
}

bool is_pow2(uint32_t v) { return v != 0 && (v & (v - 1)) == 0; }

// How long a segment may stay un-ready before remove_stale() takes its creator for dead. Creation takes
// microseconds; a minute leaves room for a creator that is descheduled on a loaded 2-core machine.
constexpr time_t kCreationGraceS = 60;

}  // namespace

SegmentHeader make_header(const SegmentParams& p, uint64_t epoch) {
  const SegmentLayout l = compute_layout(p);
  SegmentHeader h{};
  h.magic = kSegmentMagic;
  h.layout_version = kLayoutVersion;
  h.header_bytes = sizeof(SegmentHeader);
  h.boost_version = BOOST_VERSION;
  h.request_record_bytes = sizeof(RequestRecord);
  h.completion_record_bytes = sizeof(CompletionRecord);
  const std::string cid = compiler_id();
  std::memcpy(h.compiler, cid.data(), std::min<size_t>(cid.size(), kCompilerIdBytes - 1));
  h.segment_bytes = l.total_bytes;
  h.request_capacity = p.request_capacity;
  h.completion_capacity = p.completion_capacity;
  h.slot_count = p.slot_count;
  h.slot_bytes = l.slot_bytes;
  h.request_ring_offset = l.request_ring_offset;
  h.completion_ring_offset = l.completion_ring_offset;
  h.slots_offset = l.slots_offset;
  h.epoch = epoch;
  h.texture_count = p.texture_count;
  h.texture_table_fingerprint = p.texture_table_fingerprint;
  return h;
}

Status validate_header(const SegmentHeader& h, uint64_t mapped_bytes) {
  auto hex = [](uint64_t v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "0x%016llx", static_cast<unsigned long long>(v));
    return std::string(buf);
  };
  if (h.magic != kSegmentMagic) return header_error("magic", hex(h.magic), hex(kSegmentMagic));
  if (h.layout_version != kLayoutVersion) {
    return header_error("layout_version", std::to_string(h.layout_version), std::to_string(kLayoutVersion));
  }
  if (h.header_bytes != sizeof(SegmentHeader)) {
    return header_error("header_bytes", std::to_string(h.header_bytes), std::to_string(sizeof(SegmentHeader)));
  }
  if (h.boost_version != BOOST_VERSION) {
    return header_error("boost_version", std::to_string(h.boost_version), std::to_string(BOOST_VERSION));
  }
  if (h.request_record_bytes != sizeof(RequestRecord)) {
    return header_error("request_record_bytes", std::to_string(h.request_record_bytes),
                        std::to_string(sizeof(RequestRecord)));
  }
  if (h.completion_record_bytes != sizeof(CompletionRecord)) {
    return header_error("completion_record_bytes", std::to_string(h.completion_record_bytes),
                        std::to_string(sizeof(CompletionRecord)));
  }
  const std::string cid = compiler_id().substr(0, kCompilerIdBytes - 1);
  const std::string theirs(h.compiler, strnlen(h.compiler, kCompilerIdBytes));
  if (theirs != cid) return header_error("compiler", "'" + theirs + "'", "'" + cid + "'");
  if (!is_pow2(h.request_capacity) || h.request_capacity > kMaxRingCapacity) {
    return header_error("request_capacity", std::to_string(h.request_capacity), "a power of two <= 65536");
  }
  if (!is_pow2(h.completion_capacity) || h.completion_capacity > kMaxRingCapacity) {
    return header_error("completion_capacity", std::to_string(h.completion_capacity), "a power of two <= 65536");
  }
  if (h.slot_count == 0 || h.slot_count > kMaxSlotCount) {
    return header_error("slot_count", std::to_string(h.slot_count), "1..16384");
  }
  if (h.slot_bytes == 0 || h.slot_bytes > kMaxSlotBytes || h.slot_bytes % kSlotAlignment != 0) {
    return header_error("slot_bytes", std::to_string(h.slot_bytes), "a multiple of 4096 <= 64 MiB");
  }
  // Every offset is recomputed from the sizes: a header may not place a region anywhere else.
  const SegmentLayout l = compute_layout({h.request_capacity, h.completion_capacity, h.slot_count, h.slot_bytes});
  if (h.request_ring_offset != l.request_ring_offset) {
    return header_error("request_ring_offset", std::to_string(h.request_ring_offset),
                        std::to_string(l.request_ring_offset));
  }
  if (h.completion_ring_offset != l.completion_ring_offset) {
    return header_error("completion_ring_offset", std::to_string(h.completion_ring_offset),
                        std::to_string(l.completion_ring_offset));
  }
  if (h.slots_offset != l.slots_offset) {
    return header_error("slots_offset", std::to_string(h.slots_offset), std::to_string(l.slots_offset));
  }
  if (h.segment_bytes != l.total_bytes) {
    return header_error("segment_bytes", std::to_string(h.segment_bytes), std::to_string(l.total_bytes));
  }
  if (h.segment_bytes > mapped_bytes) {
    return header_error("segment_bytes", std::to_string(h.segment_bytes),
                        "at most the mapped size " + std::to_string(mapped_bytes));
  }
  return ok_status();
}

// Faults the whole mapping in, writable, without touching a byte (MADV_POPULATE_WRITE, Linux 5.14). tmpfs
// files are sparse: truncate() reserves nothing, so a segment larger than the free space of /dev/shm used to
// be created without complaint, and the first write past the free space raised SIGBUS in whichever process
// made it, mostly the server copying a mip into a slot (a crash loop, each restart dying the same way). Here
// the kernel refuses with EFAULT instead, and the creator reports it naming the size and the keys. In the
// attacher the pages exist already: this fills its page tables in one call, not one trap per 4 KiB of a slot
// inside the server's copies (the server used to do the same for the slots in 2 MiB steps while idle).
// Kernels before 5.14 (EINVAL) fault on first touch, as before.
Status populate(const std::string& name, void* base, uint64_t bytes) {
  if (::madvise(base, bytes, MADV_POPULATE_WRITE) == 0 || errno == EINVAL) return ok_status();
  const std::string why = errno == EFAULT ? "/dev/shm has less free space than that"
                                          : std::string("MADV_POPULATE_WRITE: ") + std::strerror(errno);
  return make_error(ErrorCode::kIo, "shared segment '" + name + "': cannot back its " + std::to_string(bytes) +
                                        " bytes with memory (" + why +
                                        "): make /dev/shm larger or lower protocol.staging_slot_count x "
                                        "protocol.staging_slot_bytes");
}

Result<std::unique_ptr<Segment>> Segment::create(const std::string& name, const SegmentParams& params) {
  if (!is_pow2(params.request_capacity) || params.request_capacity > kMaxRingCapacity ||
      !is_pow2(params.completion_capacity) || params.completion_capacity > kMaxRingCapacity || params.slot_count == 0 ||
      params.slot_count > kMaxSlotCount || params.slot_bytes == 0 || params.slot_bytes > kMaxSlotBytes) {
    return make_error(ErrorCode::kInvalidArgument, "segment '" + name +
                                                       "': ring capacities must be powers of two <= 65536, "
                                                       "slot_count 1..16384, slot_bytes 1..64 MiB");
  }
  std::unique_ptr<Segment> seg(new Segment());
  seg->impl_ = std::make_unique<Impl>();
  seg->name_ = name;
  const SegmentLayout layout = compute_layout(params);
  try {
    seg->impl_->shm = bip::shared_memory_object(bip::create_only, name.c_str(), bip::read_write);
    seg->owner_ = true;
    seg->impl_->shm.truncate(static_cast<bip::offset_t>(layout.total_bytes));
    seg->impl_->region = bip::mapped_region(seg->impl_->shm, bip::read_write);
  } catch (const bip::interprocess_exception& e) {
    if (e.get_error_code() == bip::already_exists_error) {
      const std::optional<uint32_t> owner = live_owner(name);
      return make_error(ErrorCode::kIo, "cannot create shared segment '" + name + "': it exists" +
                                            (owner ? " and belongs to a live renderer, pid " + std::to_string(*owner)
                                                   : std::string(" (left by a renderer that died, or being created "
                                                                 "by another one now)")) +
                                            "; give each renderer its own protocol.segment_name");
    }
    return make_error(ErrorCode::kIo, "cannot create shared segment '" + name + "': " + e.what());
  }
  auto* base = static_cast<std::byte*>(seg->impl_->region.get_address());
  if (auto st = populate(name, base, layout.total_bytes); !st.ok()) return st.error();
  std::random_device rd;
  const uint64_t epoch = (uint64_t{rd()} << 32) ^ rd() ^ static_cast<uint64_t>(getpid());
  const SegmentHeader h = make_header(params, epoch);
  // truncate() zero-fills; construct the atomics in place so their lifetime begins in this process.
  std::memcpy(base, &h, sizeof h);
  auto* rb = new (base + layout.renderer_block_offset) RendererBlock{};
  new (base + layout.server_block_offset) ServerBlock{};
  new (base + layout.request_ring_offset) RingControl{};
  new (base + layout.completion_ring_offset) RingControl{};
  rb->pid = static_cast<uint32_t>(getpid());
  rb->start_time = process_start_time(getpid()).value_or(0);
  seg->header_copy_ = h;
  seg->base_ = base;
  seg->renderer_block_ = rb;
  seg->server_block_ = reinterpret_cast<ServerBlock*>(base + layout.server_block_offset);
  seg->request_control_ = reinterpret_cast<RingControl*>(base + layout.request_ring_offset);
  seg->request_records_ = reinterpret_cast<RequestRecord*>(base + layout.request_ring_offset + sizeof(RingControl));
  seg->completion_control_ = reinterpret_cast<RingControl*>(base + layout.completion_ring_offset);
  seg->completion_records_ =
      reinterpret_cast<CompletionRecord*>(base + layout.completion_ring_offset + sizeof(RingControl));
  // release: pairs with the server's acquire-load of `ready` in open(); publishes header and blocks.
  rb->ready.v.store(1, std::memory_order_release);
  return seg;
}

Result<std::unique_ptr<Segment>> Segment::open(const std::string& name) {
  std::unique_ptr<Segment> seg(new Segment());
  seg->impl_ = std::make_unique<Impl>();
  seg->name_ = name;
  uint64_t mapped = 0;
  try {
    seg->impl_->shm = bip::shared_memory_object(bip::open_only, name.c_str(), bip::read_write);
    bip::offset_t size = 0;
    if (!seg->impl_->shm.get_size(size) || size < static_cast<bip::offset_t>(kSegmentHeaderBytes + 128)) {
      return make_error(ErrorCode::kProtocol, "shared segment '" + name + "' is too small (" + std::to_string(size) +
                                                  " bytes) to hold a header");
    }
    seg->impl_->region = bip::mapped_region(seg->impl_->shm, bip::read_write);
    mapped = seg->impl_->region.get_size();
  } catch (const bip::interprocess_exception& e) {
    return make_error(ErrorCode::kNotFound, "cannot open shared segment '" + name + "': " + e.what());
  }
  auto* base = static_cast<std::byte*>(seg->impl_->region.get_address());
  auto* rb = reinterpret_cast<RendererBlock*>(base + kSegmentHeaderBytes);
  // acquire: pairs with the creator's release-store of `ready`.
  if (rb->ready.v.load(std::memory_order_acquire) != 1) {
    return make_error(ErrorCode::kProtocol,
                      "shared segment '" + name + "' is not ready (its creator has not finished)");
  }
  std::memcpy(&seg->header_copy_, base, sizeof(SegmentHeader));  // read once; only the copy is used
  if (auto st = validate_header(seg->header_copy_, mapped); !st.ok()) {
    return make_error(ErrorCode::kProtocol, "shared segment '" + name + "': " + st.error().message);
  }
  if (auto st = populate(name, base, seg->header_copy_.segment_bytes); !st.ok()) return st.error();
  const SegmentHeader& h = seg->header_copy_;
  seg->base_ = base;
  seg->renderer_block_ = rb;
  seg->server_block_ = reinterpret_cast<ServerBlock*>(base + kSegmentHeaderBytes + sizeof(RendererBlock));
  seg->request_control_ = reinterpret_cast<RingControl*>(base + h.request_ring_offset);
  seg->request_records_ = reinterpret_cast<RequestRecord*>(base + h.request_ring_offset + sizeof(RingControl));
  seg->completion_control_ = reinterpret_cast<RingControl*>(base + h.completion_ring_offset);
  seg->completion_records_ = reinterpret_cast<CompletionRecord*>(base + h.completion_ring_offset + sizeof(RingControl));
  return seg;
}

Segment::~Segment() {
  if (owner_) bip::shared_memory_object::remove(name_.c_str());
}

std::span<std::byte> Segment::slot(uint32_t index) {
  TS_ASSERT(index < header_copy_.slot_count, "slot %u out of range (%u slots)", index, header_copy_.slot_count);
  return {base_ + header_copy_.slots_offset + uint64_t{index} * header_copy_.slot_bytes, header_copy_.slot_bytes};
}

void Segment::reset_after_server_death() {
  TS_ASSERT(owner_, "only the segment's creator may reset it");
  // The server block's pid word is the claim a waiting standalone server takes by compare-and-swap from 0:
  // it keeps the dead server's pid while the rings, the epoch and the rest of the block are reset, and is
  // freed last, so a new server never sees the dead one's ring positions (docs/design/test_time_bounds.md).
  new (request_control_) RingControl{};
  new (completion_control_) RingControl{};
  std::random_device rd;
  header_copy_.epoch = (uint64_t{rd()} << 32) ^ rd();
  // The header is otherwise read-only; only the epoch changes, and only while no server is attached.
  reinterpret_cast<SegmentHeader*>(base_)->epoch = header_copy_.epoch;
  ServerBlock& b = *server_block_;
  // relaxed: published by the release-store of `pid` below.
  for (auto* w : {&b.attached, &b.sleeping, &b.refused_by}) w->v.store(0, std::memory_order_relaxed);
  for (auto* w : {&b.start_time, &b.heartbeat, &b.completions, &b.requests_received, &b.requests_cancelled,
                  &b.ram_cache_hits, &b.ram_cache_misses, &b.bytes_read, &b.syscalls}) {
    w->v.store(0, std::memory_order_relaxed);
  }
  for (auto& w : b.loading) w.v.store(0, std::memory_order_relaxed);
  // release: pairs with the claiming server's acq_rel compare-and-swap (Server::run): whoever takes the
  // segment next sees every reset above.
  b.pid.v.store(0, std::memory_order_release);
}

bool Segment::remove(const std::string& name) { return bip::shared_memory_object::remove(name.c_str()); }

namespace {

enum class Liveness { kGone, kLive, kStale };

// A segment name's state: kGone (no such name), kLive (its renderer is alive, or it may be being created
// right now), kStale (its renderer is dead, or it was left half-created longer than kCreationGraceS ago).
// `owner` gets the renderer's pid when the header says it.
Liveness segment_liveness(const std::string& name, uint32_t* owner = nullptr) {
  // A segment that is not `ready` may be one another process is creating right now (shm_open, truncate and
  // the header take microseconds): it counts as stale only once it is older than kCreationGrace.
  struct stat st {};
  if (::stat(("/dev/shm/" + name).c_str(), &st) != 0) return Liveness::kGone;
  const bool old_enough = ::time(nullptr) - st.st_ctime > kCreationGraceS;
  try {
    bip::shared_memory_object shm(bip::open_only, name.c_str(), bip::read_only);
    bip::offset_t size = 0;
    if (!shm.get_size(size) || size < static_cast<bip::offset_t>(kSegmentHeaderBytes + sizeof(RendererBlock))) {
      return old_enough ? Liveness::kStale : Liveness::kLive;  // a creator died before truncate()
    }
    bip::mapped_region region(shm, bip::read_only, 0, kSegmentHeaderBytes + sizeof(RendererBlock));
    const auto* rb = reinterpret_cast<const RendererBlock*>(static_cast<const std::byte*>(region.get_address()) +
                                                            kSegmentHeaderBytes);
    // acquire: pairs with the creator's release-store of `ready`; pid and start time are valid after it.
    if (rb->ready.v.load(std::memory_order_acquire) != 1) return old_enough ? Liveness::kStale : Liveness::kLive;
    if (owner) *owner = rb->pid;
    return process_alive(static_cast<int>(rb->pid), rb->start_time) ? Liveness::kLive : Liveness::kStale;
  } catch (const bip::interprocess_exception&) {
    return Liveness::kLive;  // unreadable: not ours to judge
  }
}

}  // namespace

int Segment::remove_stale(const std::string& prefix) {
  int removed = 0;
  DIR* dir = ::opendir("/dev/shm");
  if (!dir) return 0;
  while (dirent* e = ::readdir(dir)) {
    const std::string name = e->d_name;
    if (name.rfind(prefix, 0) != 0) continue;
    if (segment_liveness(name) == Liveness::kStale && bip::shared_memory_object::remove(name.c_str())) ++removed;
  }
  ::closedir(dir);
  return removed;
}

bool Segment::remove_if_stale(const std::string& name) {
  return segment_liveness(name) == Liveness::kStale && bip::shared_memory_object::remove(name.c_str());
}

std::optional<uint32_t> Segment::live_owner(const std::string& name) {
  uint32_t pid = 0;
  if (segment_liveness(name, &pid) != Liveness::kLive || pid == 0) return std::nullopt;
  return pid;
}

}  // namespace texstream
