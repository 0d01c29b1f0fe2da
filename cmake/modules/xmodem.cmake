# xmodem module: XModem program transfer (core library cnc_bridge_xmodem, its tests; the cnc_dnc
# tool and sim_haas_serial are declared in cmake/modules/tools.cmake, dnc_node in dnc.cmake).
cnc_core_module(cnc_bridge_xmodem
  src/core/xmodem/packet.cpp
  src/core/xmodem/session.cpp
  src/core/xmodem/file_transfer.cpp)

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

# The tools as a user runs them: cnc_dnc and sim_haas_serial xmodem as processes over a pty.
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_xmodem_cli test/unit/test_xmodem_cli.cpp)
  if(TARGET test_xmodem_cli)
    target_link_libraries(test_xmodem_cli cnc_bridge_xmodem)
    target_compile_definitions(test_xmodem_cli PRIVATE CNC_DNC="$<TARGET_FILE:cnc_dnc>"
                                                       XMODEM_TEST_DATA="${PROJECT_SOURCE_DIR}/test/data/xmodem"
                                                       SIM_HAAS_SERIAL="$<TARGET_FILE:sim_haas_serial>")
    add_dependencies(test_xmodem_cli cnc_dnc sim_haas_serial)
  endif()
endif()

if(NOT CNC_BRIDGE_CORE_ONLY AND CATKIN_ENABLE_TESTING)
  # dnc_node (cmake/modules/dnc.cmake) sending and receiving through the simulated Haas.
  find_package(rostest REQUIRED)
  add_rostest_gtest(test_dnc_node test/rostest/dnc_node.test test/rostest/test_dnc_node.cpp)
  target_link_libraries(test_dnc_node ${catkin_LIBRARIES} ${GTEST_LIBRARIES})
  add_dependencies(test_dnc_node dnc_node sim_haas_serial ${PROJECT_NAME}_generate_messages_cpp)
endif()

# The serial control profiles of config/controls/ through dnc_node.launch onto a pty.
if(NOT CNC_BRIDGE_CORE_ONLY AND CATKIN_ENABLE_TESTING)
  add_rostest(test/rostest/control_profiles.test DEPENDENCIES dnc_node ${PROJECT_NAME}_generate_messages_py)
endif()

# The port doctor (src/core/transport/port_doctor.cpp) and `cnc_dnc doctor` on ptys and the simulated punch.
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_port_doctor test/unit/test_port_doctor.cpp)
  if(TARGET test_port_doctor)
    target_link_libraries(test_port_doctor cnc_bridge_common yaml-cpp util)
    target_compile_definitions(test_port_doctor PRIVATE CNC_DNC="$<TARGET_FILE:cnc_dnc>"
      SIM_HAAS_SERIAL="$<TARGET_FILE:sim_haas_serial>" CONTROLS_DIR="${PROJECT_SOURCE_DIR}/config/controls")
    add_dependencies(test_port_doctor cnc_dnc sim_haas_serial)
  endif()
endif()
