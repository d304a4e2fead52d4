# texstream-bench storage: the texture server in-process against its own nginx on loopback (storage_bench.cpp);
# shares the nginx launcher, broken fake origin and renderer-side harness with the storage integration tests.
target_link_libraries(texstream-bench PRIVATE texstream::server spdlog::spdlog fmt::fmt)
target_include_directories(texstream-bench PRIVATE ${PROJECT_SOURCE_DIR}/tests/integration)
target_compile_definitions(texstream-bench PRIVATE TEXSTREAM_STORAGE_BENCH_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
# Its Fig. 12 phase (storage_fig12.cpp) runs texstream-render over a camera path through nginx and measures
# image error with the path bench's runner and analysis (path_runner.cpp, path_analysis.cpp; added once, by
# whichever of bench_path.cmake and this file comes first).
get_target_property(_bench_sources_now texstream-bench SOURCES)
foreach(_shared path_analysis.cpp path_runner.cpp)
  if(NOT ${CMAKE_CURRENT_LIST_DIR}/${_shared} IN_LIST _bench_sources_now)
    target_sources(texstream-bench PRIVATE ${CMAKE_CURRENT_LIST_DIR}/${_shared})
  endif()
endforeach()
target_sources(texstream-bench PRIVATE ${CMAKE_CURRENT_LIST_DIR}/storage_fig12.cpp)
target_link_libraries(texstream-bench PRIVATE texstream::renderer)
foreach(_bin texstream-gen texstream-render texstream-server)
  if(TARGET ${_bin})
    add_dependencies(texstream-bench ${_bin})
  endif()
endforeach()
