# The renderer's streaming side without Vulkan: the shared-memory client (StreamClient), the server
# supervisor (ServerProcess) and the per-texture state machine of seed 000 (TextureStates).
# Included by renderer/CMakeLists.txt (and, until then, by tests/unit/stream_tests.cmake). Paths use
# CMAKE_CURRENT_LIST_DIR (this file's folder, renderer/) so the fragment works from any including directory.
add_library(texstream_stream STATIC
  ${CMAKE_CURRENT_LIST_DIR}/src/texture_states.cpp
  ${CMAKE_CURRENT_LIST_DIR}/src/server_process.cpp
  ${CMAKE_CURRENT_LIST_DIR}/src/stream_client.cpp
  ${CMAKE_CURRENT_LIST_DIR}/src/adaptive_controller.cpp)
add_library(texstream::stream ALIAS texstream_stream)
target_include_directories(texstream_stream PUBLIC ${CMAKE_CURRENT_LIST_DIR}/include)
target_link_libraries(texstream_stream
  PUBLIC texstream::protocol texstream::common
  PRIVATE texstream::warnings spdlog::spdlog)
