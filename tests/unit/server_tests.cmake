# texture_server unit tests: the RAM cache and its policies, the request scheduler, the slot pool, the rate
# limiter, DDS layouts, texel conversion, the open-file cache and the cache's pools (small payloads, policy
# nodes) — no shared memory, no clock.
texstream_add_unit_test(server_unit_tests
  ${CMAKE_CURRENT_LIST_DIR}/server_mip_cache_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/server_level_eviction_policy_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/server_token_bucket_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/server_formats_unit_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/server_request_scheduler_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/server_flat_mip_map_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/server_slot_pool_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/server_open_file_cache_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/server_tail_read_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/server_small_payload_pool_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/server_node_pool_test.cpp)
target_link_libraries(server_unit_tests PRIVATE texstream::server)
