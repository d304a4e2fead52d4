# Issue 9: recovery with the real server, a hostile fake server, and the real server over a corpus of damaged
# texture files (tools/chaos builds the corpus).
if(NOT TARGET texstream_stream)
  include(${PROJECT_SOURCE_DIR}/renderer/stream.cmake)
endif()

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

# Named kill points. Until the lead includes texture_server/fault.cmake, the server library lacks
# fault_point.cpp and the test compiles it in itself.
if(TARGET texstream_server)
  get_target_property(_server_sources texstream_server SOURCES)
  set(_fault_src)
  if(NOT _server_sources MATCHES "fault_point\\.cpp")
    set(_fault_src ${PROJECT_SOURCE_DIR}/texture_server/src/fault_point.cpp)
  endif()
  texstream_add_integration_test(chaos_fault_point_tests ${CMAKE_CURRENT_LIST_DIR}/chaos_fault_point_test.cpp
                                 ${_fault_src})
  target_link_libraries(chaos_fault_point_tests PRIVATE texstream::server texstream::common spdlog::spdlog)
endif()
