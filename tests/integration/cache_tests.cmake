# Sparse texture cache (issue 6) end to end: texstream-render + texstream-server on lavapipe with validation:
# the memory budget under thrashing (per-frame checks in cache.json), both formats, a budget too small to hold
# one layer's texture (a clear error), and convergence of a static view (two runs, N and 3N frames).
texstream_add_integration_test(cache_integration_tests ${CMAKE_CURRENT_LIST_DIR}/cache_sparse_test.cpp)
target_link_libraries(cache_integration_tests PRIVATE nlohmann_json::nlohmann_json texstream_stb texstream::common)
foreach(_bin texstream-render texstream-server texstream-gen)
  if(TARGET ${_bin})
    add_dependencies(cache_integration_tests ${_bin})
  endif()
endforeach()
