# MTConnect (docs/mtconnect_node.md): the client core (documents, HTTP framing, the follower, the
# machine model), mtconnect_node, tests on the responses recorded from the reference agent.
find_package(tinyxml2 REQUIRED)
cnc_core_module(cnc_bridge_mtconnect src/core/mtconnect/documents.cpp src/core/mtconnect/http.cpp src/core/mtconnect/follower.cpp
                src/core/mtconnect/machine_model.cpp)
target_link_libraries(cnc_bridge_mtconnect PUBLIC tinyxml2::tinyxml2)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_mtconnect test/unit/test_mtconnect_documents.cpp test/unit/test_mtconnect_http.cpp
    test/unit/test_mtconnect_follower.cpp test/unit/test_mtconnect_model.cpp)
  target_link_libraries(test_mtconnect cnc_bridge_mtconnect)
  target_compile_definitions(test_mtconnect PRIVATE MTCONNECT_TEST_DATA="${PROJECT_SOURCE_DIR}/test/data/mtconnect")
endif()
if(NOT CNC_BRIDGE_CORE_ONLY)
  cnc_node(mtconnect_node src/ros/nodes/mtconnect_node.cpp src/ros/nodes/mtconnect_params.cpp)
  target_link_libraries(mtconnect_node cnc_bridge_mtconnect)
  if(CATKIN_ENABLE_TESTING)
    find_package(rostest REQUIRED)
    # The node against the reference agent's recorded answers, replayed byte for byte.
    add_rostest(test/rostest/mtconnect_node.test DEPENDENCIES mtconnect_node ${PROJECT_NAME}_generate_messages_py)
  endif()
endif()
