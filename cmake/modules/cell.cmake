# The cell's own view (docs/cell_monitor.md): the ROS-free rules of "may a robot enter this machine".
cnc_core_module(cnc_bridge_cell src/core/cell/cell_rules.cpp)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_cell_rules test/unit/test_cell_rules.cpp)
  target_link_libraries(test_cell_rules cnc_bridge_cell)
endif()
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
