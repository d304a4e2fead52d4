# visibility_bench.cpp: the renderer's passes offline (render::ViewRenderer); --device picks a profile in
# config/ (lavapipe.toml or gpu.toml).
target_link_libraries(texstream-bench PRIVATE texstream::renderer spdlog::spdlog)
target_compile_definitions(texstream-bench PRIVATE TEXSTREAM_VIS_CONFIG_DIR="${PROJECT_SOURCE_DIR}/config")
