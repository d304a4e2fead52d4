# texstream-bench path (issue 8), no GPU: image error (MSE, PSNR, SSIM against analytic values and a direct
# 2-D window sum), the frames.csv round trip, and the analysis (rates, recovery after a cut, path sections,
# lock-step comparison). Links the renderer library for image_metrics/frame_log, never creating a device.
texstream_add_unit_test(bench_path_unit_tests
  ${CMAKE_CURRENT_LIST_DIR}/bench_path_image_metrics_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/bench_path_analysis_test.cpp
  ${PROJECT_SOURCE_DIR}/tools/bench/path_analysis.cpp)
target_include_directories(bench_path_unit_tests PRIVATE ${PROJECT_SOURCE_DIR}/tools/bench)
target_link_libraries(bench_path_unit_tests PRIVATE texstream::renderer)
