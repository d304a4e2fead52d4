#include "texstream/server/cache/payload_bytes.hpp"

#include <algorithm>
#include <cstring>
#include <new>
#include <utility>

#include "texstream/common/contract.hpp"
#include "texstream/server/cache/cache_arena.hpp"
#include "texstream/server/cache/small_payload_pool.hpp"

namespace texstream::server {

PayloadBytes::PayloadBytes(std::shared_ptr<CacheArena> arena, std::byte* block, size_t size)
    : data_(block), size_(size), arena_(std::move(arena)) {
  TS_ASSERT(arena_ != nullptr && arena_->owns(block), "a payload block that is not the arena's");
}

PayloadBytes::PayloadBytes(std::shared_ptr<SmallPayloadPool> pool, std::byte* memory, size_t size)
    : data_(memory), size_(size), pool_(std::move(pool)) {
  TS_ASSERT(pool_ != nullptr && memory != nullptr, "a small payload that is not the pool's");
}

PayloadBytes::~PayloadBytes() { release(); }

PayloadBytes::PayloadBytes(PayloadBytes&& other) noexcept
    : data_(std::exchange(other.data_, nullptr)),
      size_(std::exchange(other.size_, 0)),
      arena_(std::move(other.arena_)),
      pool_(std::move(other.pool_)) {}

PayloadBytes& PayloadBytes::operator=(PayloadBytes&& other) noexcept {
  if (this != &other) {
    release();
    data_ = std::exchange(other.data_, nullptr);
    size_ = std::exchange(other.size_, 0);
    arena_ = std::move(other.arena_);
    pool_ = std::move(other.pool_);
  }
  return *this;
}

void PayloadBytes::release() {
  if (data_ == nullptr) return;
  if (arena_) {
    arena_->free(data_, size_);
    arena_.reset();
  } else if (pool_) {
    pool_->free(data_, size_);
    pool_.reset();
  } else {
    ::operator delete[](data_);
  }
  data_ = nullptr;
  size_ = 0;
}

void PayloadBytes::resize(size_t n) {
  TS_ASSERT(arena_ == nullptr && pool_ == nullptr, "resizing an arena or pool payload");
  if (n == size_) return;
  std::byte* fresh = n == 0 ? nullptr : static_cast<std::byte*>(::operator new[](n));
  if (data_ != nullptr && fresh != nullptr) std::memcpy(fresh, data_, std::min(n, size_));
  release();
  data_ = fresh;
  size_ = n;
}

void PayloadBytes::assign(size_t n, std::byte value) {
  if (arena_ == nullptr && pool_ == nullptr) resize(n);
  TS_ASSERT(n == size_, "assigning %zu bytes to an arena payload of %zu", n, size_);
  std::memset(data_, std::to_integer<int>(value), n);
}

}  // namespace texstream::server
