#include "texstream/server/storage/open_file_cache.hpp"

namespace texstream::server {

std::optional<OpenTextureFile> OpenFileCache::take(TextureId id) {
  std::lock_guard lock(mutex_);
  auto it = open_.find(id.value);
  if (it == open_.end()) return std::nullopt;
  OpenTextureFile out = std::move(it->second.file);
  lru_.erase(it->second.lru);
  open_.erase(it);
  return out;
}

void OpenFileCache::give_back(TextureId id, OpenTextureFile file) {
  OpenTextureFile closing;  // destroyed (closed) after the lock is released
  std::lock_guard lock(mutex_);
  if (capacity_ == 0 || open_.count(id.value) != 0) {
    closing = std::move(file);
    return;
  }
  if (open_.size() >= capacity_) {
    auto victim = open_.find(lru_.back());
    closing = std::move(victim->second.file);
    open_.erase(victim);
    lru_.pop_back();
  }
  lru_.push_front(id.value);
  open_.emplace(id.value, Entry{std::move(file), lru_.begin()});
}

uint32_t OpenFileCache::size() const {
  std::lock_guard lock(mutex_);
  return static_cast<uint32_t>(open_.size());
}

}  // namespace texstream::server
