#include "texstream/server/storage/counting_storage.hpp"

namespace texstream::server {

class CountingStorage::File final : public StorageFile {
 public:
  File(std::unique_ptr<StorageFile> f, CountingStorage& s) : f_(std::move(f)), s_(s) {}
  Result<uint64_t> read_at(std::span<std::byte> out, uint64_t offset) override {
    s_.reads_.fetch_add(1, std::memory_order_relaxed);  // relaxed: statistic
    s_.bytes_.fetch_add(out.size(), std::memory_order_relaxed);
    return f_->read_at(out, offset);
  }
  Result<uint64_t> size() override { return f_->size(); }
  bool remote() const override { return f_->remote(); }
  bool lazy() const override { return f_->lazy(); }
  bool local(uint64_t offset, uint64_t bytes) override { return f_->local(offset, bytes); }

 private:
  std::unique_ptr<StorageFile> f_;
  CountingStorage& s_;
};

Result<std::unique_ptr<StorageFile>> CountingStorage::open(const std::filesystem::path& path) {
  auto f = inner_.open(path);
  if (!f.ok()) return f.error();
  return std::unique_ptr<StorageFile>(std::make_unique<File>(std::move(f.value()), *this));
}

}  // namespace texstream::server
