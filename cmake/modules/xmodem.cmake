# xmodem module: XModem program transfer (core library cnc_bridge_xmodem, the cnc_dnc tool, the
# sim_haas_serial xmodem mode, dnc_node).
cnc_core_module(cnc_bridge_xmodem
  src/xmodem/packet.cpp
  src/xmodem/session.cpp
  src/xmodem/file_transfer.cpp)

if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_xmodem test/unit/test_xmodem.cpp)
  target_link_libraries(test_xmodem cnc_bridge_xmodem yaml-cpp)
  target_compile_definitions(test_xmodem PRIVATE XMODEM_TEST_DATA="${PROJECT_SOURCE_DIR}/test/data/xmodem")
  # Interop with lrzsz (sx/rx) and python3-xmodem over pty pairs.
  cnc_core_gtest(test_xmodem_interop test/unit/test_xmodem_interop.cpp)
  target_link_libraries(test_xmodem_interop cnc_bridge_xmodem)
  target_compile_definitions(test_xmodem_interop PRIVATE XMODEM_TEST_DATA="${PROJECT_SOURCE_DIR}/test/data/xmodem")
endif()

# libFuzzer target: the receiver's packet parser and the receiver on arbitrary input.
cnc_fuzz_target(fuzz_xmodem_receiver test/fuzz/fuzz_xmodem_receiver.cpp)
if(CNC_BRIDGE_FUZZ)
  target_link_libraries(fuzz_xmodem_receiver cnc_bridge_xmodem)
endif()

# cnc_dnc: the ROS-free transfer tool (subcommands in a table in src/cli/cnc_dnc.cpp).
cnc_tool(cnc_dnc src/cli/cnc_dnc.cpp src/cli/cnc_dnc_doctor.cpp)
target_link_libraries(cnc_dnc cnc_bridge_xmodem cnc_bridge_programs)

# The tools as a user runs them: cnc_dnc and sim_haas_serial xmodem as processes over a pty.
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_xmodem_cli test/unit/test_xmodem_cli.cpp)
  if(TARGET test_xmodem_cli)
    target_link_libraries(test_xmodem_cli cnc_bridge_xmodem)
    target_compile_definitions(test_xmodem_cli PRIVATE CNC_DNC="$<TARGET_FILE:cnc_dnc>"
                                                       SIM_HAAS_SERIAL="$<TARGET_FILE:sim_haas_serial>")
    add_dependencies(test_xmodem_cli cnc_dnc sim_haas_serial)
  endif()
endif()

# sim_haas_serial xmodem: the Haas of the capture.
target_sources(sim_haas_serial PRIVATE src/sim/haas_serial/xmodem_mode.cpp)
target_link_libraries(sim_haas_serial cnc_bridge_xmodem)

if(NOT CNC_BRIDGE_CORE_ONLY)
  cnc_node(dnc_node src/nodes/dnc_node.cpp src/nodes/dnc_transfer_action.cpp)
  target_link_libraries(dnc_node cnc_bridge_xmodem cnc_bridge_programs)
  if(CATKIN_ENABLE_TESTING)
    find_package(rostest REQUIRED)
    add_rostest_gtest(test_dnc_node test/rostest/dnc_node.test test/rostest/test_dnc_node.cpp)
    target_link_libraries(test_dnc_node ${catkin_LIBRARIES} ${GTEST_LIBRARIES})
    add_dependencies(test_dnc_node dnc_node sim_haas_serial ${PROJECT_NAME}_generate_messages_cpp)
  endif()
endif()

# The serial control profiles of config/controls/ through dnc_node.launch onto a pty.
if(NOT CNC_BRIDGE_CORE_ONLY AND CATKIN_ENABLE_TESTING)
  add_rostest(test/rostest/control_profiles.test DEPENDENCIES dnc_node ${PROJECT_NAME}_generate_messages_py)
endif()

# The port doctor (src/transport/port_doctor.cpp) and `cnc_dnc doctor` on ptys and the simulated punch.
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_port_doctor test/unit/test_port_doctor.cpp)
  if(TARGET test_port_doctor)
    target_link_libraries(test_port_doctor cnc_bridge_common yaml-cpp util)
    target_compile_definitions(test_port_doctor PRIVATE CNC_DNC="$<TARGET_FILE:cnc_dnc>"
      SIM_HAAS_SERIAL="$<TARGET_FILE:sim_haas_serial>" CONTROLS_DIR="${PROJECT_SOURCE_DIR}/config/controls")
    add_dependencies(test_port_doctor cnc_dnc sim_haas_serial)
  endif()
endif()
