# Named kill points for texstream-chaos (issue 9): fault_point.hpp says how TEXSTREAM_FAULT and
# TEXSTREAM_FAULT_ARM arm them. To be included at the end of CMakeLists.txt, like remote.cmake.
target_sources(texstream_server PRIVATE ${CMAKE_CURRENT_LIST_DIR}/src/fault_point.cpp)
