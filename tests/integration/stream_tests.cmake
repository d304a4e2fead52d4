
texstream_add_integration_test(stream_integration_tests
  ${CMAKE_CURRENT_LIST_DIR}/stream_client_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/stream_server_process_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/stream_real_server_test.cpp)
target_link_libraries(stream_integration_tests PRIVATE texstream::stream texstream::protocol texstream::common)
if(TARGET texstream-server)
  add_dependencies(stream_integration_tests texstream-server)
endif()
