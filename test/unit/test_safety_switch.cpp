// SafetySwitch: the one design of a node's motion (and kill) switch: the value, who changed it,
// the refusal naming the service and parameter, listeners called on each change, and the gate
// under which a change and its listeners run as one step.
#include <gtest/gtest.h>

#include <atomic>
#include <future>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "cnc_bridge/common/safety_switch.h"

using namespace cnc_bridge;

namespace
{
SafetySwitch::Names millNames()
{
  return SafetySwitch::Names{"motion", "/cell/mill/set_motion_enabled", "/cell/mill/enable_motion"};
}
}  // namespace

TEST(SafetySwitch, TheRefusalNamesTheServiceAndTheStartUpParameter)
{
  const SafetySwitch motion(millNames(), false);
  EXPECT_FALSE(motion.enabled());
  EXPECT_EQ(motion.refusal("job"),
            "job refused: motion is disabled; enable it with /cell/mill/set_motion_enabled (std_srvs/SetBool, data: "
            "true), or start the node with the parameter /cell/mill/enable_motion true");
  EXPECT_EQ(motion.lastChange(), "start-up value of /cell/mill/enable_motion");
  EXPECT_EQ(SafetySwitch(SafetySwitch::Names{"kill", "", ""}, false).refusal("kill"), "kill refused: kill is disabled");
}

TEST(SafetySwitch, AChangeIsKeptWithWhoMadeItAndTheListenersHearItInOrder)
{
  SafetySwitch motion(millNames(), true);
  std::vector<std::string> heard;
  motion.subscribe([&](bool enabled, const std::string& by) { heard.push_back("a " + std::to_string(enabled) + by); });
  motion.subscribe([&](bool enabled, const std::string& by) { heard.push_back("b " + std::to_string(enabled) + by); });

  EXPECT_TRUE(motion.set(false, "/cell_manager", "12.5"));  // the value before
  EXPECT_FALSE(motion.enabled());
  EXPECT_EQ(motion.disabledBy(), "/cell_manager");
  EXPECT_EQ(motion.lastChange(), "disabled by /cell_manager at 12.5");
  EXPECT_FALSE(motion.set(true, "/operator"));
  EXPECT_EQ(motion.lastChange(), "enabled by /operator");
  EXPECT_EQ(motion.disabledBy(), "/cell_manager");  // who disabled it last, kept
  EXPECT_EQ(heard, (std::vector<std::string>{"a 0/cell_manager", "b 0/cell_manager", "a 1/operator", "b 1/operator"}));
}

TEST(SafetySwitch, AnUnsubscribedListenerIsNotCalledAgain)
{
  SafetySwitch motion(millNames(), false);
  int calls = 0;
  const SafetySwitch::Subscription subscription = motion.subscribe([&](bool, const std::string&) { ++calls; });
  motion.set(true, "/operator");
  motion.unsubscribe(subscription);
  motion.set(false, "/operator");
  EXPECT_EQ(calls, 1);
}

// A gated action (one started under gate()) sees a change only with every effect of its
// listeners: here another thread asks for the gate while a listener runs; it gets it only once
// the listener has finished.
TEST(SafetySwitch, AChangeAndItsListenersAreOneStepForAGatedAction)
{
  SafetySwitch motion(millNames(), true);
  std::atomic<bool> listener_done{false};
  std::future<bool> gated;
  motion.subscribe(
      [&](bool, const std::string&)
      {
        gated = std::async(std::launch::async,
                           [&]
                           {
                             const auto gate = motion.gate();
                             return listener_done.load();
                           });
        // The listener's effect (pausing a board) takes a while; the gated thread must wait for it.
        for (int i = 0; i < 1000; ++i)
        {
          std::this_thread::yield();
        }
        listener_done = true;
      });
  motion.set(false, "/cell_manager");
  EXPECT_TRUE(gated.get());
}

// A listener may take the gate itself (it is recursive): the ethernut node's listener pauses the
// board through the same helpers a gated service uses.
TEST(SafetySwitch, AListenerMayTakeTheGate)
{
  SafetySwitch motion(millNames(), true);
  bool ran = false;
  motion.subscribe(
      [&](bool enabled, const std::string&)
      {
        const auto gate = motion.gate();
        ran = !enabled;
      });
  motion.set(false, "/cell_manager");
  EXPECT_TRUE(ran);
}
