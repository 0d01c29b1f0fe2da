// The request boundary (cnc_bridge/ros/request_boundary.h, test/rostest/request_boundary.test):
// a handler or an execute function that throws gives a failed answer or an aborted goal with a
// message naming the call and the error, and the next call is served. Services and the action
// server live in this test process; the calls go through the ROS master like any client's.
#include <actionlib/client/simple_action_client.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <std_srvs/Empty.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>

#include <atomic>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>

#include "cnc_bridge/SendProgram.h"
#include "cnc_bridge/TransferAction.h"
#include "cnc_bridge/ros/request_boundary.h"
#include "cnc_bridge/ros/runtime_switch.h"
#include "cnc_bridge/ros/single_goal_action_server.h"

namespace
{
using cnc_bridge::advertiseGuardedService;

bool contains(const std::string& text, const std::string& part)
{
  return text.find(part) != std::string::npos;
}

// A handler that throws unless its file is "good".
bool sendHandler(cnc_bridge::SendProgram::Request& request, cnc_bridge::SendProgram::Response& response)
{
  if (request.file == "bad")
    throw std::ios_base::failure("basic_filebuf::underflow error reading the file: Is a directory");
  if (request.file == "int")
    throw 42;
  response.success = true;
  response.message = "sent " + request.file;
  response.bytes = 7;
  return true;
}

struct Handlers
{
  bool empty(std_srvs::Empty::Request&, std_srvs::Empty::Response&) { throw std::runtime_error("empty broke"); }
};
}  // namespace

TEST(RequestBoundary, AnExceptionInAServiceWithSuccessAndMessageIsAFailedAnswerNamingTheRequest)
{
  ros::NodeHandle pnh("~");
  ros::ServiceServer server = advertiseGuardedService<cnc_bridge::SendProgram>(pnh, "send", &sendHandler);
  ros::ServiceClient client = pnh.serviceClient<cnc_bridge::SendProgram>("send");
  ASSERT_TRUE(client.waitForExistence(ros::Duration(10)));

  cnc_bridge::SendProgram srv;
  srv.request.file = "bad";
  ASSERT_TRUE(client.call(srv)) << "the caller gets the answer, not a transport error";
  EXPECT_FALSE(srv.response.success);
  EXPECT_EQ(srv.response.bytes, 0u);
  EXPECT_TRUE(contains(srv.response.message, pnh.resolveName("send") + " (file: bad")) << srv.response.message;
  EXPECT_TRUE(contains(srv.response.message, "Is a directory")) << srv.response.message;

  srv.request.file = "int";
  ASSERT_TRUE(client.call(srv));
  EXPECT_FALSE(srv.response.success);
  EXPECT_TRUE(contains(srv.response.message, "not a std::exception")) << srv.response.message;

  srv.request.file = "good";  // served at once
  ASSERT_TRUE(client.call(srv));
  EXPECT_TRUE(srv.response.success) << srv.response.message;
  EXPECT_EQ(srv.response.bytes, 7u);
}

TEST(RequestBoundary, AnExceptionInAServiceWithoutAMessageFieldFailsTheCall)
{
  ros::NodeHandle pnh("~");
  Handlers handlers;
  ros::ServiceServer server = advertiseGuardedService(pnh, "empty", &Handlers::empty, &handlers);
  ros::ServiceClient client = pnh.serviceClient<std_srvs::Empty>("empty");
  ASSERT_TRUE(client.waitForExistence(ros::Duration(10)));
  std_srvs::Empty srv;
  EXPECT_FALSE(client.call(srv));
  EXPECT_FALSE(client.call(srv)) << "served again (the server is alive)";
}

TEST(RequestBoundary, ALongOrBinaryRequestIsDescribedInOneBoundedLine)
{
  cnc_bridge::SendProgram::Request request;
  request.file = std::string(65536, 'x') + "\n\xff";
  request.protocol = "xmodem";
  const std::string text = cnc_bridge::boundary::describe(request);
  EXPECT_LE(text.size(), 260u);
  EXPECT_EQ(text.find('\n'), std::string::npos);
  EXPECT_EQ(text.rfind("file: xxx", 0), 0u) << text;
}

TEST(RequestBoundary, ARuntimeSwitchIsServedThroughTheBoundary)
{
  ros::NodeHandle pnh("~switch");
  cnc_bridge::RuntimeSwitch motion(pnh, "motion", "enable_motion", "enable_motion");
  ros::ServiceClient client = pnh.serviceClient<std_srvs::SetBool>("enable_motion");
  ASSERT_TRUE(client.waitForExistence(ros::Duration(10)));
  std_srvs::SetBool srv;
  srv.request.data = true;
  ASSERT_TRUE(client.call(srv));
  EXPECT_TRUE(srv.response.success);
  EXPECT_TRUE(motion.enabled());
}

TEST(RequestBoundary, AnExceptionInAGoalAbortsItWithTheMessageAndTheNextGoalRuns)
{
  ros::NodeHandle pnh("~");
  using Server = cnc_bridge::SingleGoalActionServer<cnc_bridge::TransferAction>;
  std::unique_ptr<Server> server;
  server = std::make_unique<Server>(
      pnh, "transfer",
      [&server](const cnc_bridge::TransferGoalConstPtr& goal)
      {
        if (goal->file == "bad")
          throw std::ios_base::failure("basic_filebuf::underflow error reading the file: Is a directory");
        cnc_bridge::TransferResult result;
        result.success = true;
        result.message = "sent " + goal->file;
        server->setSucceeded(result, result.message);
      },
      [](const cnc_bridge::TransferGoal& goal) { return goal.direction + " " + goal.file; });
  server->start();

  actionlib::SimpleActionClient<cnc_bridge::TransferAction> client(pnh, "transfer", false);
  ASSERT_TRUE(client.waitForServer(ros::Duration(10)));
  cnc_bridge::TransferGoal goal;
  goal.direction = "send";
  goal.file = "bad";
  client.sendGoal(goal);
  ASSERT_TRUE(client.waitForResult(ros::Duration(10)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ABORTED);
  const std::string message = client.getResult()->message;
  EXPECT_FALSE(client.getResult()->success);
  EXPECT_TRUE(contains(message, pnh.resolveName("transfer") + " goal ")) << message;
  EXPECT_TRUE(contains(message, "(send bad)")) << message;
  EXPECT_TRUE(contains(message, "Is a directory")) << message;

  goal.file = "good";  // accepted and run at once: the server was freed
  client.sendGoal(goal);
  ASSERT_TRUE(client.waitForResult(ros::Duration(10)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client.getResult()->message;
  server->shutdown();
}

// A node whose goals share a resource with its services (dnc_node's port) admits a goal only once
// it has reserved it: a goal while the resource is held is rejected with the node's own refusal
// and never runs; an admitted goal holds the resource while it runs and frees it before its result.
TEST(SingleGoalActionServer, AGoalIsAdmittedByItsReservationAndReleasedBeforeItsResult)
{
  ros::NodeHandle pnh("~");
  using Server = cnc_bridge::SingleGoalActionServer<cnc_bridge::TransferAction>;
  std::mutex port_mutex;
  std::string port_holder;  // "" while the port is free
  std::atomic<int> executed{0};
  std::atomic<bool> held_while_running{false};
  std::unique_ptr<Server> server;
  server = std::make_unique<Server>(
      pnh, "admitted_transfer",
      [&](const cnc_bridge::TransferGoalConstPtr& goal)
      {
        ++executed;
        {
          std::lock_guard<std::mutex> lock(port_mutex);
          held_while_running = port_holder == "goal " + goal->file;
        }
        cnc_bridge::TransferResult result;
        result.success = true;
        result.message = "sent " + goal->file;
        server->setSucceeded(result, result.message);
      },
      [](const cnc_bridge::TransferGoal& goal) { return goal.direction + " " + goal.file; });
  server->setAdmission(
      [&](const std::string&, const cnc_bridge::TransferGoal& goal)
      {
        std::lock_guard<std::mutex> lock(port_mutex);
        if (!port_holder.empty())
          return "refused: the port is held by " + port_holder;
        port_holder = "goal " + goal.file;
        return std::string();
      },
      [&]
      {
        std::lock_guard<std::mutex> lock(port_mutex);
        port_holder.clear();
      });
  server->start();

  actionlib::SimpleActionClient<cnc_bridge::TransferAction> client(pnh, "admitted_transfer", false);
  ASSERT_TRUE(client.waitForServer(ros::Duration(10)));
  {
    std::lock_guard<std::mutex> lock(port_mutex);
    port_holder = "a service call";
  }
  cnc_bridge::TransferGoal goal;
  goal.direction = "send";
  goal.file = "O01234.nc";
  client.sendGoal(goal);
  ASSERT_TRUE(client.waitForResult(ros::Duration(10)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::REJECTED);
  EXPECT_EQ(client.getResult()->message, "refused: the port is held by a service call");
  EXPECT_EQ(executed, 0);

  {
    std::lock_guard<std::mutex> lock(port_mutex);
    port_holder.clear();
  }
  client.sendGoal(goal);
  ASSERT_TRUE(client.waitForResult(ros::Duration(10)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client.getResult()->message;
  EXPECT_EQ(executed, 1);
  EXPECT_TRUE(held_while_running);
  {
    std::lock_guard<std::mutex> lock(port_mutex);
    EXPECT_EQ(port_holder, "");  // freed before the result went out
  }
  server->shutdown();
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_request_boundary");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  const int status = RUN_ALL_TESTS();
  spinner.stop();
  return status;
}
