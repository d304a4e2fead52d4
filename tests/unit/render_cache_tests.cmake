# Sparse cache bookkeeping (issue 6, no GPU): page reference counts, deferred unbinds, the slot budget, batch
# folding, and the allocator's budget eviction in ring order.
texstream_add_unit_test(render_cache_unit_tests
  ${CMAKE_CURRENT_LIST_DIR}/render_cache_page_table_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_cache_budget_eviction_test.cpp)
target_link_libraries(render_cache_unit_tests PRIVATE texstream::renderer)
