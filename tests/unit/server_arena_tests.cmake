# The RAM cache's warm arena (texture_server/src/cache/cache_arena.cpp): the buddy allocator's invariants.
texstream_add_unit_test(server_arena_unit_tests ${CMAKE_CURRENT_LIST_DIR}/server_cache_arena_test.cpp)
target_link_libraries(server_arena_unit_tests PRIVATE texstream::server)
