#pragma once
// The bytes of one cached mip: on the heap, or in a block of the cache's warm arena (cache_arena.hpp). Keeps
// the small part of std::vector's interface the cache's users need (resize, assign, data, size, a span).
//
// resize() leaves new bytes uninitialised: a payload is always overwritten by a read or a copy right after it
// is sized; zeroing it first was one more full pass over every byte a miss delivers (measured with
// texstream-bench server: misses were 0.05-0.08x plain read()). Move-only.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

namespace texstream::server {

class CacheArena;
class SmallPayloadPool;

class PayloadBytes {
 public:
  PayloadBytes() = default;
  // Takes a block of `arena` (from CacheArena::allocate(size)); the block goes back to the arena with this.
  PayloadBytes(std::shared_ptr<CacheArena> arena, std::byte* block, size_t size);
  // Takes memory of `pool` (from SmallPayloadPool::allocate(size)); it goes back to the pool with this.
  PayloadBytes(std::shared_ptr<SmallPayloadPool> pool, std::byte* memory, size_t size);
  ~PayloadBytes();
  PayloadBytes(PayloadBytes&& other) noexcept;
  PayloadBytes& operator=(PayloadBytes&& other) noexcept;
  PayloadBytes(const PayloadBytes&) = delete;
  PayloadBytes& operator=(const PayloadBytes&) = delete;

  // Heap payloads only (an arena block has a fixed size): reallocates, keeping the first min(old, n) bytes.
  void resize(size_t n);
  void assign(size_t n, std::byte value);

  std::byte* data() { return data_; }
  const std::byte* data() const { return data_; }
  size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  std::byte& front() { return data_[0]; }
  const std::byte& front() const { return data_[0]; }
  std::byte* begin() { return data_; }
  std::byte* end() { return data_ + size_; }
  const std::byte* begin() const { return data_; }
  const std::byte* end() const { return data_ + size_; }
  operator std::span<std::byte>() { return {data_, size_}; }  // NOLINT(google-explicit-constructor): vector-like
  operator std::span<const std::byte>() const { return {data_, size_}; }  // NOLINT(google-explicit-constructor)
  // In an arena block of its own (not a small payload: those share slabs of the arena, see in_pool()).
  bool in_arena() const { return arena_ != nullptr; }
  bool in_pool() const { return pool_ != nullptr; }

 private:
  void release();

  std::byte* data_ = nullptr;
  size_t size_ = 0;
  std::shared_ptr<CacheArena> arena_;       // non-null: data_ is an arena block
  std::shared_ptr<SmallPayloadPool> pool_;  // non-null: data_ is the pool's; both null: from operator new[]
};

}  // namespace texstream::server
