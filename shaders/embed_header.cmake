# Writes the text of shared_structs.h into a C++ header as a raw string (run at build time by shaders/
# CMakeLists.txt), so texstream-render can tell when the header it was compiled with differs from the one its
# run-time shader compiler finds on disk.
file(READ "${INPUT}" _text)
string(FIND "${_text}" ")TSRAW\"" _clash)
if(NOT _clash EQUAL -1)
  message(FATAL_ERROR "${INPUT} contains the raw-string delimiter )TSRAW\"")
endif()
file(WRITE "${OUTPUT}.tmp" "// Generated from shaders/shared_structs.h by shaders/embed_header.cmake. Do not edit.\n#pragma once\n#include <string_view>\nnamespace texstream::render {\ninline constexpr std::string_view kSharedStructsSource = R\"TSRAW(${_text})TSRAW\";\n}  // namespace texstream::render\n")
file(COPY_FILE "${OUTPUT}.tmp" "${OUTPUT}" ONLY_IF_DIFFERENT)
