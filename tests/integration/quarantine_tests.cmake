
add_executable(quarantine_fake_server ${CMAKE_CURRENT_LIST_DIR}/quarantine_fake_server.cpp)
target_link_libraries(quarantine_fake_server PRIVATE texstream::protocol texstream::common texstream::warnings)

texstream_add_integration_test(stream_crash_quarantine_tests ${CMAKE_CURRENT_LIST_DIR}/stream_crash_quarantine_test.cpp)
target_link_libraries(stream_crash_quarantine_tests PRIVATE texstream::stream texstream::protocol texstream::common)
add_dependencies(stream_crash_quarantine_tests quarantine_fake_server)
if(TARGET texstream-server)
  add_dependencies(stream_crash_quarantine_tests texstream-server)
endif()
