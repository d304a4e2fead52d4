// The compacted list (seed 000 §3.3) as compact.comp and the read-back shaders see it: a counter, the
// indirect dispatch of the prefix copy, then the entries (CompactListHeader + CompactEntry[] in C++).
#define COMPACT_LIST_BLOCK(name, binding_number, qualifier)                                           \
  layout(set = 0, binding = binding_number, std430) qualifier buffer name {                            \
    uint count; /* may run past capacity: entries past it are dropped, the CPU reads min(count, cap) */ \
    uint dispatch_x;                                                                                    \
    uint dispatch_y;                                                                                    \
    uint dispatch_z;                                                                                    \
    CompactEntry entries[];                                                                             \
  }
