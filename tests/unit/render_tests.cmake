# Renderer (no GPU): shader compilation, shared struct layout, cache region allocator, staging ring, mip-level
# and weight formulas, broad phase, visibility list. Linked against the renderer library but never creating a
# Vulkan instance.
texstream_add_unit_test(render_unit_tests
  ${CMAKE_CURRENT_LIST_DIR}/render_shader_compile_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_struct_layout_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_cache_allocator_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_staging_ring_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_mip_math_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_broad_phase_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_visibility_list_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_interactive_test.cpp)
target_link_libraries(render_unit_tests PRIVATE texstream::renderer)
