// libFuzzer: the page file's reader (common's PageFile::load, the server's PageReader over it). Input = a file's
// bytes. Invariants: never a crash; a file that loads has a stored root, every stored page's range inside the
// file and of the page's size, every stored page's parent stored; PageReader reads exactly that range.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <vector>

#include "fuzz_support.hpp"
#include "texstream/common/page_file.hpp"
#include "texstream/server/load/page_reader.hpp"
#include "texstream/server/storage/storage.hpp"

namespace {

using namespace texstream;
using fuzz::check;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::MemoryStorage storage;
  storage.bytes = std::span(reinterpret_cast<const std::byte*>(data), size);
  auto reader = server::PageReader::open(storage, "fuzz.tspages");
  if (!reader.ok()) return 0;
  const pages::PageFile& f = reader.value()->file();
  const pages::PageGeometry& g = f.geometry();
  check(f.stored({0, 0, 0}));
  // Bounded work per input: the first slots (a loaded file's index is as large as its quadtree).
  std::vector<std::byte> page(g.page_bytes() + 16, std::byte{0x5a});
  for (uint64_t s = 0; s < std::min<uint64_t>(g.page_slots(), 4096); ++s) {
    const pages::PageId p = g.page_of_slot(s);
    const auto e = f.entry(p);
    if (!e) continue;
    check(e->bytes == g.page_bytes() && e->offset <= size && size - e->offset >= e->bytes);
    if (p.level > 0) check(f.stored({p.level - 1, p.x / 2, p.y / 2}));
    auto got = reader.value()->read(p, std::span(page).first(g.page_bytes()));
    check(got.ok() && got.value() == g.page_bytes());
    check(std::memcmp(page.data(), data + e->offset, e->bytes) == 0);
    for (size_t i = g.page_bytes(); i < page.size(); ++i) check(page[i] == std::byte{0x5a});  // nothing past it
  }
  return 0;
}
