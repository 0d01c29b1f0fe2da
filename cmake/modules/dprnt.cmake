# dprnt: DPRNT output of CNC controls (Haas serial, NGC TCP/file) to typed ROS topics, the
# surface_mapper, and the DPRNT mode of sim_haas_serial.
cnc_core_module(cnc_bridge_dprnt
  src/core/dprnt/line_assembler.cpp
  src/core/dprnt/format.cpp
  src/core/dprnt/parser.cpp
  src/core/dprnt/rules.cpp
  src/core/dprnt/input.cpp
  src/core/dprnt/settings.cpp)
target_link_libraries(cnc_bridge_dprnt PUBLIC yaml-cpp)

if(CATKIN_ENABLE_TESTING AND NOT CNC_BRIDGE_CORE_ONLY)
  find_package(rostest REQUIRED)  # before any fragment's add_rostest*(); the top level finds it later
endif()

if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_dprnt test/unit/test_dprnt.cpp)
  target_link_libraries(test_dprnt cnc_bridge_dprnt)
  target_compile_definitions(test_dprnt PRIVATE CONFIG_DIR="${PROJECT_SOURCE_DIR}/config")
  cnc_core_gtest(test_dprnt_sim test/unit/test_dprnt_sim.cpp src/sim/haas_serial/dprnt_program.cpp)
  if(TARGET test_dprnt_sim)
    target_link_libraries(test_dprnt_sim cnc_bridge_dprnt)
    target_compile_definitions(test_dprnt_sim PRIVATE SIM_HAAS_SERIAL="$<TARGET_FILE:sim_haas_serial>")
    add_dependencies(test_dprnt_sim sim_haas_serial)
  endif()
endif()


cnc_fuzz_target(fuzz_dprnt_line test/fuzz/fuzz_dprnt_line.cpp)
if(CNC_BRIDGE_FUZZ)
  target_link_libraries(fuzz_dprnt_line cnc_bridge_dprnt)
endif()

# Parser throughput benchmark (bench/dprnt/run.sh runs it).
add_executable(bench_dprnt_parser bench/dprnt/bench_dprnt_parser.cpp)
target_link_libraries(bench_dprnt_parser cnc_bridge_dprnt)

if(NOT CNC_BRIDGE_CORE_ONLY)
  cnc_node(dprnt_node src/ros/nodes/dprnt_node.cpp src/ros/nodes/dprnt_params.cpp)
  target_link_libraries(dprnt_node cnc_bridge_dprnt)
  catkin_install_python(PROGRAMS scripts/surface_mapper DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
  # The part frame's fit, imported by surface_mapper from beside itself.
  install(FILES scripts/part_fit.py DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
  if(CATKIN_ENABLE_TESTING)
    add_rostest(test/rostest/dprnt_pty.test DEPENDENCIES dprnt_node sim_haas_serial ${PROJECT_NAME}_generate_messages_cpp ${PROJECT_NAME}_generate_messages_py)
    add_rostest(test/rostest/dprnt_tcp.test DEPENDENCIES dprnt_node sim_haas_serial ${PROJECT_NAME}_generate_messages_cpp ${PROJECT_NAME}_generate_messages_py)
    add_rostest(test/rostest/dprnt_grid.test DEPENDENCIES dprnt_node sim_haas_serial ${PROJECT_NAME}_generate_messages_cpp ${PROJECT_NAME}_generate_messages_py)
    add_rostest(test/rostest/dprnt_shared_port.test DEPENDENCIES dprnt_node haas_mdc_node dnc_node sim_haas_serial ${PROJECT_NAME}_generate_messages_cpp ${PROJECT_NAME}_generate_messages_py)
    add_rostest(test/rostest/dprnt_file.test DEPENDENCIES dprnt_node ${PROJECT_NAME}_generate_messages_cpp ${PROJECT_NAME}_generate_messages_py)
    # The part frame from the probe points of a known plate, and the G54 write only where enabled.
    add_rostest(test/rostest/part_frame.test DEPENDENCIES dprnt_node haas_mdc_node sim_haas_serial sim_haas_mdc
      ${PROJECT_NAME}_generate_messages_py)
  endif()
endif()
