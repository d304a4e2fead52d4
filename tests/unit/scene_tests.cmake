# Mapped scene reading (issue 6: start-up that does not grow with the scene): mapped readers against the
# reading ones, deferred mesh checks, the persisted mesh index (round trip, stale, broken), and the broad
# phase over a mapped index against one built in memory and brute force; BroadPhase::drop_unsampled (pixel
# centres, margin, runs). No GPU.
texstream_add_unit_test(scene_mapped_tests ${CMAKE_CURRENT_LIST_DIR}/scene_mapped_test.cpp)
target_link_libraries(scene_mapped_tests PRIVATE texstream::renderer)
