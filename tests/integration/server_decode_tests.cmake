# The out-of-process decoder: texstream-decode helpers driven by DecodeHelperPool (real processes), helper
# crashes and hangs as error results naming the file, and texstream-server not linking OpenImageIO.
texstream_add_integration_test(server_decode_helper_test ${CMAKE_CURRENT_LIST_DIR}/server_decode_helper_test.cpp)
target_link_libraries(server_decode_helper_test PRIVATE texstream::server OpenImageIO::OpenImageIO)
add_dependencies(server_decode_helper_test texstream-server texstream-decode)

# Issue 9: files that crashed or hung the helper twice are quarantined (the pool, and a whole Server).
texstream_add_integration_test(server_decode_quarantine_test
                               ${CMAKE_CURRENT_LIST_DIR}/server_decode_quarantine_test.cpp)
target_link_libraries(server_decode_quarantine_test PRIVATE texstream::server OpenImageIO::OpenImageIO spdlog::spdlog
                                                            fmt::fmt)
add_dependencies(server_decode_quarantine_test texstream-decode)
