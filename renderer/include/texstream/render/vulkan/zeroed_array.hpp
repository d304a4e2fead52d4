#pragma once
// A fixed-size array whose elements start as all-zero bytes, taken from calloc: an allocation this large comes
// from fresh zero pages of the kernel (glibc serves it with mmap and skips the memset), so creating it costs
// nothing per element and memory is committed only where elements are written. For per-texture tables of
// 10^6 entries of which a view touches a few thousand (TextureCache's residency).
#include <array>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <type_traits>

#include "texstream/common/contract.hpp"

namespace texstream::render {

template <class T>
class ZeroedArray {
  // calloc creates such objects implicitly (C++20 implicit-lifetime types): no constructor runs.
  static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>);

 public:
  ZeroedArray() = default;
  explicit ZeroedArray(size_t n) : data_(static_cast<T*>(std::calloc(n > 0 ? n : 1, sizeof(T)))), size_(n) {
    TS_ASSERT(data_ != nullptr, "calloc of %zu elements of %zu bytes", n, sizeof(T));
    // The elements are never constructed: T's value-initialized state must be all zero bytes.
    const T init{};
    const std::array<std::byte, sizeof(T)> zero{};
    TS_ASSERT(std::memcmp(&init, zero.data(), sizeof(T)) == 0, "ZeroedArray of a type whose default is not zero");
  }

  T& operator[](size_t i) { return data_.get()[i]; }
  const T& operator[](size_t i) const { return data_.get()[i]; }
  size_t size() const { return size_; }

 private:
  struct Free {
    void operator()(T* p) const { std::free(p); }
  };
  std::unique_ptr<T, Free> data_;
  size_t size_ = 0;
};

}  // namespace texstream::render
