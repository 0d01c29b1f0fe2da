# G-code parser: a ROS-free streaming parser shared by ethernut_node (job streaming and preview)
# and at_controller_node (path planning).
cnc_core_module(cnc_bridge_gcode src/core/gcode/lexer.cpp src/core/gcode/gcode.cpp src/core/gcode/gcode_words.cpp src/core/gcode/gcode_cycles.cpp
                src/core/gcode/gcode_comp.cpp src/core/gcode/tool_table.cpp)
target_link_libraries(cnc_bridge_gcode PUBLIC yaml-cpp)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_gcode test/unit/test_gcode.cpp test/unit/test_gcode_lexer.cpp test/unit/test_program_steps.cpp)
  target_link_libraries(test_gcode cnc_bridge_gcode)
  target_compile_definitions(test_gcode PRIVATE CNC_BRIDGE_FIXTURE_DIR="${PROJECT_SOURCE_DIR}/test/data/gcode")
endif()
cnc_fuzz_target(fuzz_gcode test/fuzz/fuzz_gcode.cpp)
cnc_tool(bench_gcode bench/gcode/bench_gcode.cpp)
target_link_libraries(bench_gcode cnc_bridge_gcode)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  # Cross-check against LinuxCNC's rs274 (Debian linuxcnc-uspace).
  cnc_core_gtest(test_gcode_rs274 test/unit/test_gcode_rs274.cpp)
  target_link_libraries(test_gcode_rs274 cnc_bridge_gcode)
  target_compile_definitions(test_gcode_rs274 PRIVATE CNC_BRIDGE_FIXTURE_DIR="${PROJECT_SOURCE_DIR}/test/data/gcode")
endif()
