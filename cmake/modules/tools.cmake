# The ROS-free command-line tools and the simulated Haas serial port, each declared here whole
# (every source, every library), after the modules whose libraries they link.

# cnc_dnc: the transfer tool a user types (subcommands in a table in src/cli/cnc_dnc.cpp): send and
# receive by XModem or over a share, drip, backup, list, doctor, replay.
cnc_tool(cnc_dnc
  src/cli/cnc_dnc.cpp
  src/cli/cnc_dnc_doctor.cpp
  src/cli/cnc_dnc_drip.cpp
  src/cli/cnc_dnc_share.cpp
  src/cli/cnc_dnc_replay.cpp)
target_link_libraries(cnc_dnc cnc_bridge_xmodem cnc_bridge_programs cnc_bridge_drip cnc_bridge_share)

# cnc_plan: the '@' path as 1 ms setpoints (CSV, PNG through scripts/plot_plan.py).
cnc_tool(cnc_plan src/cli/cnc_plan.cpp)
target_link_libraries(cnc_plan cnc_bridge_at_protocol)
target_compile_definitions(cnc_plan PRIVATE CNC_PLAN_PLOT_SCRIPT="${PROJECT_SOURCE_DIR}/scripts/plot_plan.py")
if(NOT CNC_BRIDGE_CORE_ONLY)
  # Installed beside cnc_plan, which looks for it there first (then in the source tree).
  install(PROGRAMS scripts/plot_plan.py DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
endif()

# sim_haas_serial: a Haas control's RS-232 port on a pty, one mode per use of the port (XModem,
# drip, punch, DPRNT, and all of a Classic's uses on one port).
cnc_tool(sim_haas_serial
  src/sim/haas_serial/main.cpp
  src/sim/haas_serial/xmodem_mode.cpp
  src/sim/haas_serial/drip_mode.cpp
  src/sim/haas_serial/punch_mode.cpp
  src/sim/haas_serial/dprnt_mode.cpp
  src/sim/haas_serial/dprnt_program.cpp
  src/sim/haas_serial/classic_mode.cpp)
target_link_libraries(sim_haas_serial cnc_bridge_testing cnc_bridge_sim_support cnc_bridge_xmodem cnc_bridge_dnc_sim
                      cnc_bridge_dprnt cnc_bridge_mdc_sim)
