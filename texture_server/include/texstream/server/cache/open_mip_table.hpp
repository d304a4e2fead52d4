#pragma once
// The server's per-mip tables (MipCacheTable, FlatMipMap) on common's open-addressing table, keyed by MipKey.
#include "texstream/common/open_table.hpp"
#include "texstream/server/cache/mip_key.hpp"

namespace texstream::server {

template <class Slot, class Used>
using OpenMipTable = OpenTable<Slot, Used, MipKeyHash>;

}  // namespace texstream::server
