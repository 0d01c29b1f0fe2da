# The cell's own view (docs/cell_monitor.md): the ROS-free rules of "may a robot enter this machine".
cnc_core_module(cnc_bridge_cell src/core/cell/cell_rules.cpp)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_cell_rules test/unit/test_cell_rules.cpp)
  target_link_libraries(test_cell_rules cnc_bridge_cell)
endif()
