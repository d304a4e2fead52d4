#pragma once
// The scene's texture table as the renderer's streaming side reads it: one immutable table shared by the texture
// states, the mip ledger and the stream client. In texstream-render it is a view of the mapped textures.bin
// records (no heap copy: 16 bytes per texture less, 91 MB at 5.7 M textures; docs/design/host_memory.md), kept
// alive by shared ownership of whatever holds the mapping. A vector converts implicitly (tests, tools); copies
// share. A record becomes a TextureShape on each access.
#include <cstddef>
#include <initializer_list>
#include <iterator>
#include <memory>
#include <span>
#include <utility>
#include <vector>

#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/completion_check.hpp"

namespace texstream::stream {

class TextureTable {
 public:
  TextureTable() = default;
  TextureTable(const std::vector<TextureShape>& shapes);  // NOLINT(google-explicit-constructor): a table is its shapes
  TextureTable(std::initializer_list<TextureShape> shapes) : TextureTable(std::vector<TextureShape>(shapes)) {}
  // A view of `records` (each one's format valid: map_texture_table and read_texture_table check it), which
  // stay valid as long as `owner` lives; every copy of the table holds `owner`.
  TextureTable(std::shared_ptr<const void> owner, std::span<const scene::TextureRecord> records)
      : owner_(std::move(owner)), records_(records) {}

  size_t size() const { return records_.size(); }
  bool empty() const { return records_.empty(); }
  TextureShape operator[](size_t i) const { return shape_of(records_[i]); }

  // Iterates the shapes by value (range-for binds them as `const TextureShape&` to temporaries).
  class Iterator {
   public:
    using iterator_category = std::forward_iterator_tag;
    using value_type = TextureShape;
    using difference_type = std::ptrdiff_t;
    using pointer = void;
    using reference = TextureShape;
    Iterator() = default;
    explicit Iterator(const scene::TextureRecord* at) : at_(at) {}
    TextureShape operator*() const { return shape_of(*at_); }
    Iterator& operator++() {
      ++at_;
      return *this;
    }
    Iterator operator++(int) { return Iterator(at_++); }
    bool operator==(const Iterator&) const = default;

   private:
    const scene::TextureRecord* at_ = nullptr;
  };
  Iterator begin() const { return Iterator(records_.data()); }
  Iterator end() const { return Iterator(records_.data() + records_.size()); }

 private:
  static TextureShape shape_of(const scene::TextureRecord& r) {
    return TextureShape{r.width, r.height, r.mip_count, static_cast<TexelFormat>(r.format)};
  }

  std::shared_ptr<const void> owner_;  // holds the records: a mapping, or the vector constructor's own copy
  std::span<const scene::TextureRecord> records_;
};

// The vector constructor's records: the same four fields, so a test's shape (even an invalid format) comes back
// unchanged.
inline TextureTable::TextureTable(const std::vector<TextureShape>& shapes) {
  auto records = std::make_shared<std::vector<scene::TextureRecord>>();
  records->reserve(shapes.size());
  for (const TextureShape& s : shapes) {
    records->push_back(scene::TextureRecord{s.width, s.height, s.mip_count, static_cast<uint32_t>(s.format)});
  }
  records_ = *records;
  owner_ = std::move(records);
}

}  // namespace texstream::stream
