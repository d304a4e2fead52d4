# texture_server integration tests: a Server in the test process over a real segment (the test plays the
# renderer), and the real texstream-server executable against a segment owned by a forked child.
texstream_add_integration_test(server_streaming_test ${CMAKE_CURRENT_LIST_DIR}/server_streaming_test.cpp)
target_link_libraries(server_streaming_test PRIVATE texstream::server)

texstream_add_integration_test(server_process_test ${CMAKE_CURRENT_LIST_DIR}/server_process_test.cpp)
target_link_libraries(server_process_test PRIVATE texstream::server)
add_dependencies(server_process_test texstream-server)

# The segment's rings between two real processes (fork), 10^7 records each way.
texstream_add_integration_test(server_ring_stress_test ${CMAKE_CURRENT_LIST_DIR}/server_ring_stress_test.cpp)
target_link_libraries(server_ring_stress_test PRIVATE texstream::protocol)

# TIFF / OpenEXR (made by OpenImageIO's make_texture, as maketx does) and third-party DDS files.
texstream_add_integration_test(server_formats_test ${CMAKE_CURRENT_LIST_DIR}/server_formats_test.cpp)
target_link_libraries(server_formats_test PRIVATE texstream::server OpenImageIO::OpenImageIO)
