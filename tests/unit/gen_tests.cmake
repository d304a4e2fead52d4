# Scene format (common), camera paths (common) and the procedural city generator (tools/gen).
texstream_add_unit_test(scene_format_test scene_format_test.cpp)
# OpenImageIO only here: the test proves that other tools can read the DDS files we write.
target_link_libraries(scene_format_test PRIVATE texstream::common OpenImageIO::OpenImageIO)

texstream_add_unit_test(camera_path_test camera_path_test.cpp)
target_link_libraries(camera_path_test PRIVATE texstream::common)

if(TARGET texstream_gen_lib)
  texstream_add_unit_test(generator_test generator_test.cpp)
  target_link_libraries(generator_test PRIVATE texstream_gen_lib PkgConfig::XXHASH)
endif()
