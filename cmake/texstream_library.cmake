# texstream_library(<name> SOURCES ... [INCLUDE <dir>] [PUBLIC ...] [PRIVATE ...] [DEFINES ...])
# One room of the tree = one static library texstream_<name>, alias texstream::<name>. Every room links the
# warning/sanitizer flags privately; its PUBLIC list is the set of rooms and libraries its headers expose, so
# the link graph states the layers (see ARCHITECTURE.md). INCLUDE defaults to the library's include/ folder,
# two levels up from a room's src/<room>/ folder.
function(texstream_library name)
  cmake_parse_arguments(ARG "" "INCLUDE" "SOURCES;PUBLIC;PRIVATE;DEFINES" ${ARGN})
  if(NOT ARG_INCLUDE)
    get_filename_component(ARG_INCLUDE ${CMAKE_CURRENT_SOURCE_DIR}/../../include ABSOLUTE)
  endif()
  add_library(texstream_${name} STATIC ${ARG_SOURCES})
  add_library(texstream::${name} ALIAS texstream_${name})
  target_include_directories(texstream_${name} PUBLIC ${ARG_INCLUDE})
  target_link_libraries(texstream_${name} PUBLIC ${ARG_PUBLIC} PRIVATE texstream::warnings ${ARG_PRIVATE})
  if(ARG_DEFINES)
    target_compile_definitions(texstream_${name} PUBLIC ${ARG_DEFINES})
  endif()
endfunction()

# texstream_rooms(<aggregate> <room>...): adds each room's folder (src/<room>) and an INTERFACE target
# texstream::<aggregate> that links them all, for executables and tests that use the whole library.
function(texstream_rooms aggregate)
  add_library(texstream_${aggregate} INTERFACE)
  add_library(texstream::${aggregate} ALIAS texstream_${aggregate})
  foreach(room ${ARGN})
    add_subdirectory(src/${room})
  endforeach()
  list(TRANSFORM ARGN PREPEND texstream::${aggregate}_)
  target_link_libraries(texstream_${aggregate} INTERFACE ${ARGN})
endfunction()
