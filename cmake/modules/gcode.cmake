# G-code parser: a ROS-free streaming parser shared by ethernut_node (job streaming and preview)
# and at_controller_node (path planning).
cnc_core_module(cnc_bridge_gcode src/gcode/gcode.cpp)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_gcode test/unit/test_gcode.cpp)
  target_link_libraries(test_gcode cnc_bridge_gcode)
  target_compile_definitions(test_gcode PRIVATE CNC_BRIDGE_FIXTURE_DIR="${PROJECT_SOURCE_DIR}/test/data/gcode")
endif()
cnc_fuzz_target(fuzz_gcode test/fuzz/fuzz_gcode.cpp)
