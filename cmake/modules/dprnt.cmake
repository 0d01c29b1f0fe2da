# dprnt: DPRNT output of CNC controls (Haas serial, NGC TCP/file) to typed ROS topics, the
# surface_mapper, and the DPRNT mode of sim_haas_serial.
cnc_core_module(cnc_bridge_dprnt
  src/dprnt/line_assembler.cpp
  src/dprnt/format.cpp
  src/dprnt/parser.cpp
  src/dprnt/rules.cpp
  src/dprnt/input.cpp)
target_link_libraries(cnc_bridge_dprnt PUBLIC yaml-cpp)

if(CATKIN_ENABLE_TESTING AND NOT CNC_BRIDGE_CORE_ONLY)
  find_package(rostest REQUIRED)  # before any fragment's add_rostest*(); the top level finds it later
endif()

if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_dprnt test/unit/test_dprnt.cpp)
  target_link_libraries(test_dprnt cnc_bridge_dprnt)
endif()
