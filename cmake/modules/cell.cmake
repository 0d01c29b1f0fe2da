# The cell's own view (docs/cell_monitor.md): the ROS-free rules of "may a robot enter this machine"
# and the time to cycle end (a program planned with the G-code parser and the '@' planner).
cnc_core_module(cnc_bridge_cell src/core/cell/cell_rules.cpp src/core/cell/cycle_time.cpp)
target_link_libraries(cnc_bridge_cell PUBLIC cnc_bridge_at_protocol cnc_bridge_gcode)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_cell_rules test/unit/test_cell_rules.cpp)
  target_link_libraries(test_cell_rules cnc_bridge_cell)
  cnc_core_gtest(test_cycle_time test/unit/test_cycle_time.cpp)
  target_link_libraries(test_cycle_time cnc_bridge_cell)
endif()
# The predicted cycle against the simulated '@' controller's, over the demo's programs and the CAM
# corpus (bench/cycle_time/run.sh).
cnc_tool(bench_cycle_time bench/cycle_time/bench_cycle_time.cpp)
target_link_libraries(bench_cycle_time cnc_bridge_cell)
if(NOT CNC_BRIDGE_CORE_ONLY)
  cnc_node(cell_monitor src/ros/nodes/cell_monitor_node.cpp)
  target_link_libraries(cell_monitor cnc_bridge_cell yaml-cpp)
endif()
if(CATKIN_ENABLE_TESTING AND NOT CNC_BRIDGE_CORE_ONLY)
  find_package(rostest REQUIRED)
  # cell_monitor over sim_haas_mdc and a machine with no node: grant, lease withdrawn, hold_entry.
  add_rostest(test/rostest/cell_monitor.test DEPENDENCIES cell_monitor haas_mdc_node sim_haas_mdc
    ${PROJECT_NAME}_generate_messages_cpp ${PROJECT_NAME}_generate_messages_py)
endif()
