# controller_bench.cpp: the adaptive controller lives in the renderer's no-Vulkan stream library; the stress
# sequences are shared with the unit test (tests/unit/controller_stress_sequences.hpp).
target_link_libraries(texstream-bench PRIVATE texstream::stream)
target_include_directories(texstream-bench PRIVATE ${PROJECT_SOURCE_DIR}/tests/unit)
