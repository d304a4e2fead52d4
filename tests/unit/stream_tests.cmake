
texstream_add_unit_test(stream_unit_tests ${CMAKE_CURRENT_LIST_DIR}/stream_texture_states_test.cpp)
target_link_libraries(stream_unit_tests PRIVATE texstream::stream)
