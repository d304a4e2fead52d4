#include "texstream/server/cache/node_pool.hpp"

#include "texstream/common/contract.hpp"

namespace texstream::server {

void NodePool::add_chunk(size_t blocks) {
  auto chunk = std::make_unique<Block[]>(blocks);  // value-initialised: every page written (faulted) now
  for (size_t i = blocks; i-- > 0;) {              // threaded back to front: allocation walks the chunk from its start
    chunk[i].next = free_;
    free_ = &chunk[i];
  }
  chunks_.push_back(std::move(chunk));
  capacity_ += blocks;
}

void NodePool::reserve(size_t blocks) {
  if (blocks > capacity_) add_chunk(blocks - capacity_);
}

void* NodePool::allocate() {
  if (free_ == nullptr) add_chunk(kChunkBlocks);
  Block* b = free_;
  free_ = b->next;
  ++in_use_;
  return b;
}

void NodePool::deallocate(void* p) {
  TS_ASSERT(p != nullptr && in_use_ > 0, "returning a block the node pool did not hand out");
  auto* b = static_cast<Block*>(p);
  b->next = free_;
  free_ = b;
  --in_use_;
}

}  // namespace texstream::server
