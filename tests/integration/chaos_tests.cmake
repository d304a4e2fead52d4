
texstream_add_integration_test(chaos_recovery_tests ${CMAKE_CURRENT_LIST_DIR}/chaos_recovery_test.cpp)
target_link_libraries(chaos_recovery_tests PRIVATE texstream::stream texstream::protocol texstream::common)

# No TSan for this one: the hostile peer races on purpose (it plays another process writing shared memory).
texstream_add_integration_test(chaos_hostile_server_tests ${CMAKE_CURRENT_LIST_DIR}/chaos_hostile_server_test.cpp)
target_link_libraries(chaos_hostile_server_tests PRIVATE texstream::stream texstream::protocol texstream::common)

if(TARGET texstream_chaos_lib)
  texstream_add_integration_test(chaos_corrupt_files_tests ${CMAKE_CURRENT_LIST_DIR}/chaos_corrupt_files_test.cpp)
  target_link_libraries(chaos_corrupt_files_tests PRIVATE texstream_chaos_lib texstream::stream texstream::protocol
                                                          texstream::common)
endif()
if(TARGET texstream-server)
  add_dependencies(chaos_recovery_tests texstream-server)
  if(TARGET chaos_corrupt_files_tests)
    add_dependencies(chaos_corrupt_files_tests texstream-server)
  endif()
endif()

# Named kill points (texture_server/src/support/fault_point.cpp).
if(TARGET texstream::server)
  texstream_add_integration_test(chaos_fault_point_tests ${CMAKE_CURRENT_LIST_DIR}/chaos_fault_point_test.cpp)
  target_link_libraries(chaos_fault_point_tests PRIVATE texstream::server texstream::common spdlog::spdlog)
endif()
