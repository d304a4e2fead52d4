# The adaptive streaming controller (seed 000 §3.4, Eq. 4-7): equations by hand, Fig. 4 as data, modes,
# and the stability stress / drift tests (reduced counts; texstream-bench controller runs the full ones).
if(NOT TARGET texstream_stream)
  include(${PROJECT_SOURCE_DIR}/renderer/stream.cmake)
endif()

texstream_add_unit_test(controller_unit_tests
  ${CMAKE_CURRENT_LIST_DIR}/controller_equations_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/controller_stress_test.cpp)
target_include_directories(controller_unit_tests PRIVATE ${CMAKE_CURRENT_LIST_DIR})
target_link_libraries(controller_unit_tests PRIVATE texstream::stream)
