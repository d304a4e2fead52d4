#pragma once
// The scene's texture table as the renderer's streaming side reads it: one immutable copy shared by the texture
// states, the mip ledger and the stream client (each used to hold its own: 48 bytes per texture, 274 MB at
// 5.7 M textures; docs/design/host_memory.md). A vector converts implicitly, so a caller with its own table
// (tests) passes it as before; copies share.
#include <cstddef>
#include <initializer_list>
#include <memory>
#include <utility>
#include <vector>

#include "texstream/protocol/completion_check.hpp"

namespace texstream::stream {

class TextureTable {
 public:
  TextureTable() : shapes_(std::make_shared<const std::vector<TextureShape>>()) {}
  TextureTable(std::vector<TextureShape> shapes)  // NOLINT(google-explicit-constructor): a table is its shapes
      : shapes_(std::make_shared<const std::vector<TextureShape>>(std::move(shapes))) {}
  TextureTable(std::initializer_list<TextureShape> shapes) : TextureTable(std::vector<TextureShape>(shapes)) {}

  size_t size() const { return shapes_->size(); }
  bool empty() const { return shapes_->empty(); }
  const TextureShape& operator[](size_t i) const { return (*shapes_)[i]; }
  std::vector<TextureShape>::const_iterator begin() const { return shapes_->begin(); }
  std::vector<TextureShape>::const_iterator end() const { return shapes_->end(); }

 private:
  std::shared_ptr<const std::vector<TextureShape>> shapes_;
};

}  // namespace texstream::stream
