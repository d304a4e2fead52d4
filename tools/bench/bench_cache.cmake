# cache_bench.cpp: runs texstream-render (and through it texstream-server) and reads its PNG frames, summary.json
# and cache.json; the bind microbenchmark uses the renderer library's SparseMemory. --device picks a profile in
# config/ (lavapipe.toml or gpu.toml).
target_link_libraries(texstream-bench PRIVATE texstream::renderer texstream_stb nlohmann_json::nlohmann_json)
target_compile_definitions(texstream-bench PRIVATE TEXSTREAM_CACHE_BENCH_CONFIG_DIR="${PROJECT_SOURCE_DIR}/config")
foreach(_bin texstream-render texstream-server texstream-gen)
  if(TARGET ${_bin})
    add_dependencies(texstream-bench ${_bin})
  endif()
endforeach()
