# Scene format (common), camera paths (common) and the procedural city generator (tools/gen).
texstream_add_unit_test(scene_format_test scene_format_test.cpp)
# OpenImageIO only here: the test proves that other tools can read the DDS files we write. Linked by file, not
# through OpenImageIO::OpenImageIO: Debian's imported target lists /usr/include/opencv4 in its include path,
# which does not exist without libopencv-dev and makes CMake's generate step fail. The headers are in
# /usr/include, a default search path.
target_link_libraries(scene_format_test PRIVATE texstream::common
  $<TARGET_FILE:OpenImageIO::OpenImageIO> $<TARGET_FILE:OpenImageIO::OpenImageIO_Util>)

texstream_add_unit_test(camera_path_test camera_path_test.cpp)
target_link_libraries(camera_path_test PRIVATE texstream::common)

if(TARGET texstream_gen_lib)
  texstream_add_unit_test(generator_test generator_test.cpp)
  target_link_libraries(generator_test PRIVATE texstream_gen_lib PkgConfig::XXHASH)
endif()
