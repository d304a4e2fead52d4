#include "texstream/server/load/page_reader.hpp"

namespace texstream::server {

Result<std::unique_ptr<PageReader>> PageReader::open(Storage& storage, const std::string& path) {
  auto file = storage.open(path);
  if (!file.ok()) return file.error();
  auto size = file.value()->size();
  if (!size.ok()) return size.error();
  uint64_t index_bytes = 0;
  StorageFile& f = *file.value();
  const pages::PageFile::ReadAt read = [&](std::span<std::byte> out, uint64_t offset) -> Result<uint64_t> {
    auto got = f.read_at(out, offset);
    if (!got.ok()) return got.error();
    if (got.value() != out.size())
      return make_error(ErrorCode::kCorrupt, path + ": page file ended after " + std::to_string(offset + got.value()) +
                                                 " bytes, in the middle of its index");
    index_bytes += got.value();
    return got.value();
  };
  auto index = pages::PageFile::load(read, size.value(), path);
  if (!index.ok()) return index.error();
  return std::unique_ptr<PageReader>(
      new PageReader(path, std::move(file.value()), std::move(index.value()), index_bytes));
}

bool PageReader::local(pages::PageId p) const {
  const auto e = index_.entry(p);
  return e && file_->local(e->offset, e->bytes);
}

Result<uint64_t> PageReader::read(pages::PageId p, std::span<std::byte> out) {
  const auto e = index_.entry(p);
  auto where = [&] {
    return path_ + ": level " + std::to_string(p.level) + " page " + std::to_string(p.x) + "," + std::to_string(p.y);
  };
  if (!e) return make_error(ErrorCode::kNotFound, where() + " is not stored (outside the image or the quadtree)");
  if (out.size() < e->bytes)
    return make_error(ErrorCode::kInvalidArgument, where() + ": " + std::to_string(out.size()) +
                                                       " bytes cannot hold its " + std::to_string(e->bytes));
  auto got = file_->read_at(out.first(e->bytes), e->offset);
  if (!got.ok()) return got.error();
  if (got.value() != e->bytes)
    return make_error(ErrorCode::kCorrupt, where() + ": the file ended after " + std::to_string(got.value()) +
                                               " of its " + std::to_string(e->bytes) + " bytes");
  page_bytes_read_.fetch_add(got.value(), std::memory_order_relaxed);
  return got.value();
}

}  // namespace texstream::server
