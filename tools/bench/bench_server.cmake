# texstream-bench server: the texture server in-process against a real segment, OpenImageIO's ImageCache as
# the baseline (server_bench.cpp).
target_link_libraries(texstream-bench PRIVATE texstream::server OpenImageIO::OpenImageIO spdlog::spdlog)
