#include "texstream/server/storage/caching_storage.hpp"

#include "texstream/server/storage/relative_path.hpp"

namespace texstream::server {

namespace {

class CachingFile final : public StorageFile {
 public:
  CachingFile(std::unique_ptr<StorageFile> origin, DiskCache& cache, TierCounters& counters, std::string relative)
      : origin_(std::move(origin)), cache_(cache), counters_(counters), relative_(std::move(relative)) {}

  Result<uint64_t> read_at(std::span<std::byte> out, uint64_t offset) override {
    const std::string key = DiskCache::key_of(relative_, offset, out.size());
    if (std::optional<uint64_t> got = cache_.read(key, out)) {
      counters_.bytes_from_disk_cache.fetch_add(*got, std::memory_order_relaxed);
      return *got;
    }
    Result<uint64_t> got = origin_->read_at(out, offset);
    if (!got.ok()) return got;
    counters_.bytes_from_origin.fetch_add(*got, std::memory_order_relaxed);
    cache_.insert(key, out.first(*got));
    return got;
  }
  Result<uint64_t> size() override { return origin_->size(); }
  bool remote() const override { return origin_->remote(); }
  bool local(uint64_t offset, uint64_t bytes) override {
    return !origin_->remote() || cache_.contains(DiskCache::key_of(relative_, offset, bytes));
  }

 private:
  std::unique_ptr<StorageFile> origin_;
  DiskCache& cache_;
  TierCounters& counters_;
  std::string relative_;
};

}  // namespace

CachingStorage::CachingStorage(Storage& origin, DiskCache& cache, std::filesystem::path root)
    : origin_(origin), cache_(cache), root_(std::move(root)) {}

Result<std::unique_ptr<StorageFile>> CachingStorage::open(const std::filesystem::path& path) {
  Result<std::string> rel = relative_under(path, root_);
  if (!rel.ok()) return rel.error();
  Result<std::unique_ptr<StorageFile>> f = origin_.open(path);
  if (!f.ok()) return f.error();
  return std::unique_ptr<StorageFile>(new CachingFile(std::move(f).value(), cache_, counters_, std::move(rel).value()));
}

}  // namespace texstream::server
