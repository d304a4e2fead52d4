texstream_add_unit_test(protocol_unit_tests
  ${CMAKE_CURRENT_LIST_DIR}/protocol_layout_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/spsc_ring_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/completion_check_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/protocol_checksum_test.cpp)
target_link_libraries(protocol_unit_tests PRIVATE texstream::protocol)

texstream_add_unit_test(config_unit_tests ${CMAKE_CURRENT_LIST_DIR}/config_test.cpp)
target_link_libraries(config_unit_tests PRIVATE texstream::common)
target_compile_definitions(config_unit_tests PRIVATE TEXSTREAM_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
texstream_add_unit_test(memory_info_unit_tests ${CMAKE_CURRENT_LIST_DIR}/memory_info_test.cpp)
target_link_libraries(memory_info_unit_tests PRIVATE texstream::common)
