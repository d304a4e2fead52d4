# texstream-render end to end on lavapipe with validation on, against the real texstream-server: a generated
# city (exit code, validation, frames, residency), the key image test (one camera-facing quad whose pixels must
# equal the texture's finest mip), and command-line / configuration errors.
texstream_add_integration_test(render_integration_tests
  ${CMAKE_CURRENT_LIST_DIR}/render_scene_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_quad_image_test.cpp)
target_link_libraries(render_integration_tests PRIVATE texstream::renderer nlohmann_json::nlohmann_json texstream_stb)

# GPU visibility (issue 5): analytic plane mips, extremes, textureQueryLod agreement, the id-buffer set, large
# coordinates, through the renderer's passes in-process (render::ViewRenderer); and the window under Xvfb.
texstream_add_integration_test(render_visibility_tests ${CMAKE_CURRENT_LIST_DIR}/render_visibility_test.cpp)
target_link_libraries(render_visibility_tests PRIVATE texstream::renderer nlohmann_json::nlohmann_json)
# The binaries these tests run: building the tests builds them.
foreach(_bin texstream-render texstream-server texstream-gen)
  if(TARGET ${_bin})
    add_dependencies(render_integration_tests ${_bin})
    add_dependencies(render_visibility_tests ${_bin})
  endif()
endforeach()
