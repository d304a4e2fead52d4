// The compacted list (seed 000 §3.3) as compact.comp sees it: a counter, three reserved words (the entries
// stay 16-byte aligned), then the entries (CompactListHeader + CompactEntry[] in C++).
#define COMPACT_LIST_BLOCK(name, binding_number, qualifier)                                           \
  layout(set = 0, binding = binding_number, std430) qualifier buffer name {                            \
    uint count; /* may run past capacity: entries past it are dropped, the CPU reads min(count, cap) */ \
    uint reserved_x;                                                                                    \
    uint reserved_y;                                                                                    \
    uint reserved_z;                                                                                    \
    CompactEntry entries[];                                                                             \
  }
