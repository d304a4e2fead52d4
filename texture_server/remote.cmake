# Remote and slow storage tiers (issue 4): http(s) origin (libcurl range reads), slow-storage emulation, disk
# cache, and the stack built from the [storage] configuration. Included at the end of CMakeLists.txt.
find_package(CURL REQUIRED)
target_sources(texstream_server PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/src/content_range.cpp
  ${CMAKE_CURRENT_LIST_DIR}/src/relative_path.cpp
  ${CMAKE_CURRENT_LIST_DIR}/src/http_storage.cpp
  ${CMAKE_CURRENT_LIST_DIR}/src/slow_storage.cpp
  ${CMAKE_CURRENT_LIST_DIR}/src/disk_cache.cpp
  ${CMAKE_CURRENT_LIST_DIR}/src/caching_storage.cpp
  ${CMAKE_CURRENT_LIST_DIR}/src/storage_stack.cpp)
target_link_libraries(texstream_server PRIVATE CURL::libcurl PkgConfig::XXHASH)
