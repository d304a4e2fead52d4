# Start-up that follows the view (issue 6), on lavapipe in-process (render::ViewRenderer): an opened (mapped)
# generated city draws exactly what the loaded one draws (in place and through staging), with and without
# mesh_index.bin; dropping meshes that cover no pixel centre changes no pixel and no metadata; a corrupt mesh is
# reported by the frame that first needs it. TEXSTREAM_SCENE_1M=<dir> adds the drop check on a 10^6-mesh view.
texstream_add_integration_test(scene_open_tests ${CMAKE_CURRENT_LIST_DIR}/scene_open_test.cpp)
target_link_libraries(scene_open_tests PRIVATE texstream::renderer)
if(TARGET texstream-gen)
  add_dependencies(scene_open_tests texstream-gen)
endif()

# The draw list (issue 5, few draws): adjacent meshes merged per viewport part in index order, absolute indices
# and per-vertex mesh ids, instances drawn alone, other shared ranges refused (SceneGpu on lavapipe).
texstream_add_integration_test(scene_draws_tests ${CMAKE_CURRENT_LIST_DIR}/scene_draws_test.cpp)
target_link_libraries(scene_draws_tests PRIVATE texstream::renderer)
