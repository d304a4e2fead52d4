# Streaming side of the renderer (no Vulkan): the texture state machine of seed 000 Algorithm 1.
# renderer/CMakeLists.txt is expected to include renderer/stream.cmake; until it does, include it here.
if(NOT TARGET texstream_stream)
  include(${PROJECT_SOURCE_DIR}/renderer/stream.cmake)
endif()

texstream_add_unit_test(stream_unit_tests ${CMAKE_CURRENT_LIST_DIR}/stream_texture_states_test.cpp)
target_link_libraries(stream_unit_tests PRIVATE texstream::stream)
