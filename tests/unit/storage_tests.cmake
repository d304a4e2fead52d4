# Issue 4 unit tests: Content-Range parsing, slow-storage determinism, disk cache (index, corruption,
# eviction order, folder lock). Files only; no network, shared memory or clock.
if(TARGET texstream::server)
  texstream_add_unit_test(storage_unit_tests
    ${CMAKE_CURRENT_LIST_DIR}/storage_content_range_test.cpp
    ${CMAKE_CURRENT_LIST_DIR}/storage_slow_storage_test.cpp
    ${CMAKE_CURRENT_LIST_DIR}/storage_disk_cache_test.cpp)
  target_link_libraries(storage_unit_tests PRIVATE texstream::server)
endif()
