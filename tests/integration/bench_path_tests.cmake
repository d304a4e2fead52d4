# texstream-bench path --quick end to end on a freshly generated RGBA8 city (not the default BC1 one): the
# report, raw data and summary line exist; lock-step reruns are identical; the all-resident run reproduces the
# reference frames exactly; the in-process and blocking baselines run. Also: bad arguments are refused.
if(TARGET texstream-bench)
  texstream_add_integration_test(bench_path_integration_tests ${CMAKE_CURRENT_LIST_DIR}/bench_path_test.cpp)
  target_link_libraries(bench_path_integration_tests PRIVATE nlohmann_json::nlohmann_json)
  foreach(_bin texstream-bench texstream-render texstream-render-inprocess texstream-server texstream-gen)
    if(TARGET ${_bin})
      add_dependencies(bench_path_integration_tests ${_bin})
    endif()
  endforeach()
endif()
