// Fan-out: each target's result on its own, a failure does not stop the next, a cancel stops all.
#include <gtest/gtest.h>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/programs/fan_out.h"

using namespace cnc_bridge;
using namespace cnc_bridge::programs;

TEST(FanOut, AFailingTargetIsReportedAndTheNextStillRuns)
{
  std::vector<std::string> called;
  std::vector<std::string> reported;
  const auto results = fanOut(
      {"vf2", "down", "st10"},
      [&](const std::string& target) -> std::string
      {
        called.push_back(target);
        if (target == "down")
          throw LinkError("connection refused: no SMB server answers on down:445");
        return "sent to " + target;
      },
      [&](const TargetResult& r) { reported.push_back(r.target); });
  EXPECT_EQ(called, (std::vector<std::string>{"vf2", "down", "st10"}));
  EXPECT_EQ(reported, called);
  ASSERT_EQ(results.size(), 3u);
  EXPECT_TRUE(results[0].success);
  EXPECT_EQ(results[0].message, "sent to vf2");
  EXPECT_FALSE(results[1].success);
  EXPECT_EQ(results[1].message, "connection refused: no SMB server answers on down:445");
  EXPECT_TRUE(results[2].success);
  EXPECT_EQ(results[2].target, "st10");
  EXPECT_FALSE(allSucceeded(results));
  EXPECT_TRUE(allSucceeded({results[0], results[2]}));
  EXPECT_FALSE(allSucceeded({}));
}

TEST(FanOut, CancelStopsTheWholeRun)
{
  std::vector<std::string> called;
  EXPECT_THROW(fanOut({"a", "b", "c"},
                      [&](const std::string& target) -> std::string
                      {
                        called.push_back(target);
                        if (target == "b")
                          throw CancelledError("cancelled");
                        return "ok";
                      }),
               CancelledError);
  EXPECT_EQ(called, (std::vector<std::string>{"a", "b"}));
}
