# texstream-bench storage: the texture server in-process against its own nginx on loopback (storage_bench.cpp);
# shares the nginx launcher, broken fake origin and renderer-side harness with the storage integration tests.
target_link_libraries(texstream-bench PRIVATE texstream::server spdlog::spdlog fmt::fmt)
target_include_directories(texstream-bench PRIVATE ${PROJECT_SOURCE_DIR}/tests/integration)
target_compile_definitions(texstream-bench PRIVATE TEXSTREAM_STORAGE_BENCH_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
if(TARGET texstream-gen)
  add_dependencies(texstream-bench texstream-gen)
endif()
