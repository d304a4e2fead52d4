
texstream_add_unit_test(controller_unit_tests
  ${CMAKE_CURRENT_LIST_DIR}/controller_equations_test.cpp
  ${CMAKE_CURRENT_LIST_DIR}/controller_stress_test.cpp)
target_include_directories(controller_unit_tests PRIVATE ${CMAKE_CURRENT_LIST_DIR})
target_link_libraries(controller_unit_tests PRIVATE texstream::stream)
