#include "texstream/server/storage/disk_cache.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>
#include <xxhash.h>

#include <spdlog/spdlog.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>
#include <thread>
#include <vector>

namespace texstream::server {

namespace fs = std::filesystem;

namespace {

constexpr char kMagic[8] = {'T', 'S', 'D', 'C', 'A', 'C', 'H', '1'};
// Fixed entry header: magic, payload length, checksum, key length (then the key, then the payload).
struct EntryHeader {
  char magic[8];
  uint64_t payload_bytes;
  uint64_t checksum;  // XXH3-64 of key then payload
  uint64_t key_bytes;
};
static_assert(sizeof(EntryHeader) == 32);

// Journal compaction once it holds this many more lines than live entries (touches accumulate under LRU).
constexpr uint64_t kJournalSlack = 4096;

std::string errno_text() { return std::strerror(errno); }

uint64_t entry_checksum(const std::string& key, std::span<const std::byte> payload) {
  XXH3_state_t* s = XXH3_createState();
  XXH3_64bits_reset(s);
  XXH3_64bits_update(s, key.data(), key.size());
  XXH3_64bits_update(s, payload.data(), payload.size());
  const uint64_t h = XXH3_64bits_digest(s);
  XXH3_freeState(s);
  return h;
}

std::string hex16(uint64_t v) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

// A journal line: the text, a tab, the text's checksum in hex.
std::string seal(const std::string& text) { return text + "\t" + hex16(XXH3_64bits(text.data(), text.size())) + "\n"; }

bool unseal(const std::string& line, std::string& text) {
  const size_t tab = line.rfind('\t');
  if (tab == std::string::npos || line.size() - tab - 1 != 16) return false;
  text = line.substr(0, tab);
  return hex16(XXH3_64bits(text.data(), text.size())) == line.substr(tab + 1);
}

bool write_all(int fd, const void* data, size_t n) {
  const char* p = static_cast<const char*>(data);
  while (n > 0) {
    const ssize_t w = ::write(fd, p, n);
    if (w < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    p += w;
    n -= static_cast<size_t>(w);
  }
  return true;
}

bool read_all(int fd, void* data, size_t n, uint64_t offset) {
  char* p = static_cast<char*>(data);
  while (n > 0) {
    const ssize_t r = ::pread(fd, p, n, static_cast<off_t>(offset));
    if (r < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    if (r == 0) return false;
    p += r;
    n -= static_cast<size_t>(r);
    offset += static_cast<uint64_t>(r);
  }
  return true;
}

}  // namespace

std::string DiskCache::key_of(const std::string& relative_path, uint64_t offset, uint64_t length) {
  return relative_path + "@" + std::to_string(offset) + "+" + std::to_string(length);
}

Result<std::unique_ptr<DiskCache>> DiskCache::open(const fs::path& dir, uint64_t budget_bytes, DiskCachePolicy policy) {
  std::error_code ec;
  fs::create_directories(dir / "entries", ec);
  if (ec) return make_error(ErrorCode::kIo, "disk cache '" + dir.string() + "': cannot create it: " + ec.message());
  const fs::path lock_path = dir / "lock";
  const int fd = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) return make_error(ErrorCode::kIo, "disk cache '" + lock_path.string() + "': " + errno_text());
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    char pid[32] = {0};
    (void)::pread(fd, pid, sizeof pid - 1, 0);
    ::close(fd);
    if (err == EWOULDBLOCK) {
      return make_error(ErrorCode::kInvalidArgument,
                        "disk cache folder '" + dir.string() + "' is in use by another texstream-server (pid " +
                            std::string(pid) + "); give each server its own storage.disk_cache_dir");
    }
    return make_error(ErrorCode::kIo, "disk cache '" + lock_path.string() + "': flock: " + std::strerror(err));
  }
  const std::string me = std::to_string(::getpid());
  if (::ftruncate(fd, 0) != 0 || ::pwrite(fd, me.data(), me.size(), 0) != static_cast<ssize_t>(me.size())) {
    spdlog::warn("disk cache '{}': cannot write the owner pid: {}", lock_path.string(), errno_text());
  }
  std::unique_ptr<DiskCache> cache(new DiskCache(dir, budget_bytes, policy, fd));
  if (Status s = cache->load_index(); !s.ok()) return s.error();
  return cache;
}

DiskCache::DiskCache(fs::path dir, uint64_t budget, DiskCachePolicy policy, int lock_fd)
    : dir_(std::move(dir)), budget_(budget), policy_(policy), lock_fd_(lock_fd) {}

DiskCache::~DiskCache() {
  {
    std::lock_guard lock(mutex_);
    // A compact journal for the next start (also drops the touch lines); failure only costs replay time.
    if (Status s = rewrite_index_locked(); !s.ok()) spdlog::warn("{}", s.error().message);
    if (journal_fd_ >= 0) ::close(journal_fd_);
  }
  ::close(lock_fd_);  // releases the flock
}

fs::path DiskCache::entry_path(const std::string& key) const {
  return dir_ / "entries" / (hex16(XXH3_64bits(key.data(), key.size())) + ".bin");
}

Status DiskCache::load_index() {
  const fs::path index = dir_ / "index";
  // The file system's block: every entry file takes whole blocks (a 148-byte DDS header entry takes 4 KiB).
  struct statvfs fsinfo {};
  const bool have_fs = ::statvfs(dir_.c_str(), &fsinfo) == 0;
  if (have_fs && fsinfo.f_bsize >= 512 && fsinfo.f_bsize <= (1u << 20)) block_ = fsinfo.f_bsize;
  uint64_t good_bytes = 0;
  uint64_t lines = 0;
  bool torn = false;
  {
    std::ifstream in(index, std::ios::binary);
    std::string line, text;
    while (in && std::getline(in, line)) {
      if (in.eof() || !unseal(line, text)) {  // no newline at the end, or a bad checksum: torn or corrupt
        torn = true;
        break;
      }
      good_bytes += line.size() + 1;
      ++lines;
      std::istringstream fields(text);
      char op = 0;
      fields >> op;
      if (op == 'I') {
        uint64_t seq = 0, size = 0;
        fields >> seq >> size;
        fields.get();
        std::string key;
        std::getline(fields, key);
        if (auto it = entries_.find(key); it != entries_.end()) {
          order_.erase(it->second.seq);
          bytes_ -= footprint(key, it->second.size);
        }
        entries_[key] = Entry{seq, size};
        order_[seq] = key;
        bytes_ += footprint(key, size);
        next_seq_ = std::max(next_seq_, seq + 1);
      } else if (op == 'T') {
        uint64_t seq = 0;
        fields >> seq;
        fields.get();
        std::string key;
        std::getline(fields, key);
        if (auto it = entries_.find(key); it != entries_.end()) {
          order_.erase(it->second.seq);
          it->second.seq = seq;
          order_[seq] = key;
          next_seq_ = std::max(next_seq_, seq + 1);
        }
      } else if (op == 'E') {
        fields.get();
        std::string key;
        std::getline(fields, key);
        if (auto it = entries_.find(key); it != entries_.end()) {
          order_.erase(it->second.seq);
          bytes_ -= footprint(key, it->second.size);
          entries_.erase(it);
        }
      } else {
        torn = true;
        break;
      }
    }
  }
  if (torn) {
    spdlog::warn("disk cache '{}': the index is damaged after {} good lines ({} bytes); the rest is dropped",
                 index.string(), lines, good_bytes);
  }
  // Entries whose file is missing or has the wrong size are dropped; the checksum is verified on each read.
  std::vector<std::string> gone;
  for (const auto& [key, e] : entries_) {
    std::error_code ec;
    const uint64_t want = sizeof(EntryHeader) + key.size() + e.size;
    if (fs::file_size(entry_path(key), ec) != want || ec) gone.push_back(key);
  }
  for (const std::string& key : gone) {
    erase_locked(key, false);
    counters_.corrupt_dropped.fetch_add(1, std::memory_order_relaxed);
  }
  // Files no entry names (a crash between the rename and the journal line, temporaries) are deleted.
  std::unordered_map<std::string, bool> named;
  for (const auto& [key, e] : entries_) named[entry_path(key).filename().string()] = true;
  std::error_code ec;
  for (const fs::directory_entry& f : fs::directory_iterator(dir_ / "entries", ec)) {
    if (!named.count(f.path().filename().string())) fs::remove(f.path(), ec);
  }
  // A budget the file system cannot hold: lowered to its free space plus what the entries already take, less
  // a sixteenth for the index, directories and other writers. A first guess: a full disk lowers it again.
  if (have_fs && ::statvfs(dir_.c_str(), &fsinfo) == 0) {
    const uint64_t room = static_cast<uint64_t>(fsinfo.f_bavail) * fsinfo.f_frsize + bytes_;
    const uint64_t usable = room - room / 16;
    if (usable < budget_.load(std::memory_order_relaxed)) {
      spdlog::warn(
          "disk cache '{}': storage.disk_cache_bytes = {} is more than its file system can hold ({} bytes "
          "free, {} in entries already); using {}",
          dir_.string(), budget_.load(std::memory_order_relaxed), room - bytes_, bytes_, usable);
      budget_.store(usable, std::memory_order_relaxed);
    }
  }
  evict_locked();  // the budget may be smaller than last time
  if (Status s = rewrite_index_locked(); !s.ok()) return s;
  if (!gone.empty()) {
    spdlog::warn("disk cache '{}': dropped {} entries whose files were missing or torn", dir_.string(), gone.size());
  }
  spdlog::info("disk cache '{}': {} entries, {} of {} bytes ({})", dir_.string(), entries_.size(), bytes_,
               budget_.load(std::memory_order_relaxed), choice_name(policy_));
  return ok_status();
}

Status DiskCache::rewrite_index_locked() {
  const fs::path index = dir_ / "index";
  const fs::path tmp = dir_ / "index.tmp";
  std::string all;
  for (const auto& [seq, key] : order_) {
    all += seal("I " + std::to_string(seq) + " " + std::to_string(entries_.at(key).size) + " " + key);
  }
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return make_error(ErrorCode::kIo, "disk cache '" + tmp.string() + "': " + errno_text());
  const bool ok = write_all(fd, all.data(), all.size());
  ::close(fd);
  if (!ok || ::rename(tmp.c_str(), index.c_str()) != 0) {
    return make_error(ErrorCode::kIo, "disk cache '" + index.string() + "': cannot rewrite: " + errno_text());
  }
  if (journal_fd_ >= 0) ::close(journal_fd_);
  journal_fd_ = ::open(index.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
  if (journal_fd_ < 0) return make_error(ErrorCode::kIo, "disk cache '" + index.string() + "': " + errno_text());
  journal_lines_ = order_.size();
  return ok_status();
}

void DiskCache::append_locked(const std::string& line) {
  if (journal_fd_ < 0) return;
  if (append_failed_) {
    // The failed append may have left half a line, which would end the replay at the next start there (and
    // drop every entry after it): the journal is written whole instead, until that works. The state it
    // writes already holds this line's change.
    if (rewrite_index_locked().ok()) {
      append_failed_ = false;
      spdlog::info("disk cache '{}': the index is written again", dir_.string());
    }
    return;
  }
  const std::string sealed = seal(line);
  if (!write_all(journal_fd_, sealed.data(), sealed.size())) {
    spdlog::warn("disk cache '{}': cannot append to the index: {}; it is rewritten whole until that works",
                 dir_.string(), errno_text());
    append_failed_ = true;
    return;
  }
  if (++journal_lines_ > order_.size() * 2 + kJournalSlack) {
    if (Status s = rewrite_index_locked(); !s.ok()) spdlog::warn("{}", s.error().message);
  }
}

void DiskCache::erase_locked(const std::string& key, bool journal) {
  auto it = entries_.find(key);
  if (it == entries_.end()) return;
  order_.erase(it->second.seq);
  bytes_ -= footprint(key, it->second.size);
  entries_.erase(it);
  std::error_code ec;
  fs::remove(entry_path(key), ec);
  if (journal) append_locked("E " + key);
}

void DiskCache::shrink_for_space_locked() {
  const uint64_t before = budget_.load(std::memory_order_relaxed);
  // Nothing held: the disk is someone else's, and evicting cannot make room; store nothing more.
  const uint64_t lowered = bytes_ - bytes_ / 8;
  if (lowered >= before) return;
  budget_.store(lowered, std::memory_order_relaxed);
  spdlog::warn(
      "disk cache '{}': its file system is full with {} bytes of entries; budget lowered from {} to {} "
      "bytes{}",
      dir_.string(), bytes_, before, lowered, lowered == 0 ? " (the disk cache stores nothing more)" : "");
}

void DiskCache::evict_locked() {
  while (bytes_ > budget_.load(std::memory_order_relaxed) && !order_.empty()) {
    const std::string victim = order_.begin()->second;
    erase_locked(victim, true);
    counters_.evictions.fetch_add(1, std::memory_order_relaxed);
  }
}

bool DiskCache::contains(const std::string& key) const {
  std::lock_guard lock(mutex_);
  return entries_.count(key) > 0;
}

uint64_t DiskCache::footprint(const std::string& key, uint64_t payload_bytes) const {
  const uint64_t file = sizeof(EntryHeader) + key.size() + payload_bytes;
  return (file + block_ - 1) / block_ * block_;
}

uint64_t DiskCache::bytes() const {
  std::lock_guard lock(mutex_);
  return bytes_;
}

size_t DiskCache::entries() const {
  std::lock_guard lock(mutex_);
  return entries_.size();
}

std::optional<uint64_t> DiskCache::read(const std::string& key, std::span<std::byte> out) {
  uint64_t size = 0;
  {
    std::lock_guard lock(mutex_);
    auto it = entries_.find(key);
    if (it == entries_.end()) {
      counters_.misses.fetch_add(1, std::memory_order_relaxed);
      return std::nullopt;
    }
    size = it->second.size;
  }
  const fs::path path = entry_path(key);
  auto drop = [&](const std::string& why) {
    spdlog::warn("disk cache: entry '{}' ({}) dropped: {}", key, path.string(), why);
    counters_.corrupt_dropped.fetch_add(1, std::memory_order_relaxed);
    counters_.misses.fetch_add(1, std::memory_order_relaxed);
    std::lock_guard lock(mutex_);
    erase_locked(key, true);
    return std::nullopt;
  };
  if (size > out.size())
    return drop("it holds " + std::to_string(size) + " bytes, more than the " + std::to_string(out.size()) +
                " its key asks");
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    if (errno == ENOENT) {  // evicted or replaced meanwhile: a plain miss
      counters_.misses.fetch_add(1, std::memory_order_relaxed);
      return std::nullopt;
    }
    return drop("cannot open: " + errno_text());
  }
  EntryHeader h{};
  std::string stored_key;
  bool ok = read_all(fd, &h, sizeof h, 0);
  if (ok && std::memcmp(h.magic, kMagic, sizeof kMagic) == 0 && h.key_bytes == key.size() && h.payload_bytes == size) {
    stored_key.resize(h.key_bytes);
    ok = read_all(fd, stored_key.data(), stored_key.size(), sizeof h) &&
         (size == 0 || read_all(fd, out.data(), size, sizeof h + stored_key.size()));
    // A byte past the payload means the file is longer than its header says (not ours, or a torn rewrite).
    char extra;
    if (ok && ::pread(fd, &extra, 1, static_cast<off_t>(sizeof h + stored_key.size() + size)) != 0) ok = false;
  } else {
    ok = false;
  }
  ::close(fd);
  if (!ok || stored_key != key) return drop("header, key or length does not match (torn or foreign file)");
  if (entry_checksum(key, out.first(size)) != h.checksum) return drop("checksum mismatch (torn write or bit rot)");
  counters_.hits.fetch_add(1, std::memory_order_relaxed);
  counters_.bytes_hit.fetch_add(size, std::memory_order_relaxed);
  if (policy_ == DiskCachePolicy::kLru) {
    std::lock_guard lock(mutex_);
    if (auto it = entries_.find(key); it != entries_.end()) {
      order_.erase(it->second.seq);
      it->second.seq = next_seq_++;
      order_[it->second.seq] = key;
      append_locked("T " + std::to_string(it->second.seq) + " " + key);
    }
  }
  return size;
}

void DiskCache::insert(const std::string& key, std::span<const std::byte> data) {
  if (footprint(key, data.size()) > budget_.load(std::memory_order_relaxed) ||
      key.find_first_of("\n\t") != std::string::npos || key.empty())
    return;
  EntryHeader h{};
  std::memcpy(h.magic, kMagic, sizeof kMagic);
  h.payload_bytes = data.size();
  h.checksum = entry_checksum(key, data);
  h.key_bytes = key.size();
  const fs::path path = entry_path(key);
  // A temporary name unique to this thread: two workers inserting the same key never share a temporary.
  const fs::path tmp =
      path.string() + ".tmp" + std::to_string(std::hash<std::thread::id>{}(std::this_thread::get_id()));
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) {
    spdlog::warn("disk cache: cannot create '{}': {}", tmp.string(), errno_text());
    return;
  }
  const bool ok =
      write_all(fd, &h, sizeof h) && write_all(fd, key.data(), key.size()) && write_all(fd, data.data(), data.size());
  const int write_errno = errno;
  ::close(fd);
  std::error_code ec;
  if (!ok) {
    fs::remove(tmp, ec);
    if (write_errno == ENOSPC || write_errno == EDQUOT) {
      std::lock_guard lock(mutex_);
      shrink_for_space_locked();
      evict_locked();
      return;
    }
    spdlog::warn("disk cache: cannot write '{}': {}", tmp.string(), std::strerror(write_errno));
    return;
  }
  std::lock_guard lock(mutex_);
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    spdlog::warn("disk cache: cannot rename '{}': {}", tmp.string(), errno_text());
    fs::remove(tmp, ec);
    return;
  }
  if (auto it = entries_.find(key); it != entries_.end()) {  // replaced: the file is already the new one
    order_.erase(it->second.seq);
    bytes_ -= footprint(key, it->second.size);
    entries_.erase(it);
  }
  const uint64_t seq = next_seq_++;
  entries_[key] = Entry{seq, data.size()};
  order_[seq] = key;
  bytes_ += footprint(key, data.size());
  counters_.inserts.fetch_add(1, std::memory_order_relaxed);
  counters_.bytes_inserted.fetch_add(data.size(), std::memory_order_relaxed);
  append_locked("I " + std::to_string(seq) + " " + std::to_string(data.size()) + " " + key);
  evict_locked();
}

}  // namespace texstream::server
