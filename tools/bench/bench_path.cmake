# path_bench.cpp (issue 8): runs texstream-render / texstream-render-inprocess over a camera path and reads
# their frames.csv (the renderer library's frame_log), then writes report.md and calls path_report_plots.py.
# Its helpers are path_*.cpp (not *_bench.cpp, which would make them subcommands).
# path_analysis.cpp and path_runner.cpp are shared with the storage bench's Fig. 12 phase (bench_storage.cmake):
# whichever file comes first adds them.
get_target_property(_bench_sources_now texstream-bench SOURCES)
foreach(_shared path_analysis.cpp path_runner.cpp)
  if(NOT ${CMAKE_CURRENT_LIST_DIR}/${_shared} IN_LIST _bench_sources_now)
    target_sources(texstream-bench PRIVATE ${CMAKE_CURRENT_LIST_DIR}/${_shared})
  endif()
endforeach()
target_sources(texstream-bench PRIVATE ${CMAKE_CURRENT_LIST_DIR}/path_report.cpp)
target_link_libraries(texstream-bench PRIVATE texstream::renderer nlohmann_json::nlohmann_json fmt::fmt)
target_compile_definitions(texstream-bench PRIVATE TEXSTREAM_PATH_BENCH_SOURCE_DIR="${PROJECT_SOURCE_DIR}")

# texstream-render with its texture server on a thread: the in-process loader baseline. It links the server
# library, which texstream-render itself never does (DESIGN "Layout").
if(TARGET texstream::server)
  add_executable(texstream-render-inprocess
    ${CMAKE_CURRENT_LIST_DIR}/path_render_inprocess_main.cpp
    ${CMAKE_CURRENT_LIST_DIR}/path_in_process_server.cpp)
  target_include_directories(texstream-render-inprocess PRIVATE ${CMAKE_CURRENT_LIST_DIR})
  target_link_libraries(texstream-render-inprocess PRIVATE texstream::renderer texstream::server texstream::warnings
    spdlog::spdlog Threads::Threads)
  add_dependencies(texstream-bench texstream-render-inprocess)
endif()
foreach(_bin texstream-render texstream-server)
  if(TARGET ${_bin})
    add_dependencies(texstream-bench ${_bin})
  endif()
endforeach()
