# Issue 4: remote and slow storage against a real nginx on loopback (config/nginx/texstream-origin.conf.in)
# and a broken fake origin: ranges, disk cache across a restart, cache-folder lock, bimodal scheduling, and
# every origin failure with a deadline.
if(TARGET texstream::server)
  texstream_add_integration_test(storage_integration_tests ${CMAKE_CURRENT_LIST_DIR}/storage_origin_test.cpp)
  target_link_libraries(storage_integration_tests PRIVATE texstream::server texstream::protocol texstream::common
                                                          spdlog::spdlog)
  foreach(_bin texstream-gen texstream-server)
    if(TARGET ${_bin})
      add_dependencies(storage_integration_tests ${_bin})
    endif()
  endforeach()
endif()
