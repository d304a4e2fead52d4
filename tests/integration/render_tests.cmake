# texstream-render end to end on lavapipe with validation on, against the real texstream-server: a generated
# city (exit code, validation, frames, residency), the key image test (one camera-facing quad whose pixels must
# equal the texture's finest mip), and command-line / configuration errors.
texstream_add_integration_test(render_integration_tests
  ${CMAKE_CURRENT_LIST_DIR}/render_scene_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_quad_image_test.cpp)
target_link_libraries(render_integration_tests PRIVATE texstream::common nlohmann_json::nlohmann_json texstream_stb)
# The binaries these tests run: building the tests builds them.
foreach(_bin texstream-render texstream-server texstream-gen)
  if(TARGET ${_bin})
    add_dependencies(render_integration_tests ${_bin})
  endif()
endforeach()
