// The 1 ms sender: what it writes for an operation (at_protocol.md's step order), commands queued between
// setpoints, cancel as a deceleration, abort on emergency stop, and a failing link. The "controller"
// is a FakeTransport; the tests wait on the bytes it receives or on the job, never on sleeps.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <future>
#include <thread>

#include "cnc_bridge/at_protocol/sender.h"
#include "cnc_bridge/common/error.h"
#include "testing/fake_transport.h"

using namespace cnc_bridge;
using namespace cnc_bridge::at_protocol;

namespace
{
const Milliseconds kWait(10000);

std::vector<Command> decodeAll(const std::vector<uint8_t>& bytes)
{
  CommandReassembler reassembler;
  const auto result = reassembler.feed(bytes.data(), bytes.size());
  EXPECT_TRUE(result.errors.empty());
  EXPECT_EQ(reassembler.pending(), 0u);
  std::vector<Command> out;
  for (const auto& m : result.messages)
  {
    out.push_back(decodeCommand(m));
  }
  return out;
}

std::shared_ptr<const Trajectory> line(double x_mm, double feed = 20.0)
{
  return std::make_shared<Trajectory>(std::vector<Vec3>{{0, 0, 0}, {x_mm * kPulsesPerMm, 0, 0}}, feed, PlannerLimits{});
}

struct Fixture : ::testing::Test
{
  std::shared_ptr<FakeTransport> link = std::make_shared<FakeTransport>("controller:7000");
  std::string link_error;
  std::promise<void> link_failed;
  SetpointSender sender{SetpointSender::Options{0.001, 0, Milliseconds(200),
                                                [this](const std::string& why)
                                                {
                                                  link_error = why;
                                                  link_failed.set_value();
                                                }}};
  void SetUp() override { sender.setLink(link); }
};
}  // namespace

TEST_F(Fixture, AnOperationIsWrittenInTheProtocolsOrder)
{
  Operation operation;
  operation.coolant = true;
  operation.tool = ToolChange{2, 45};
  operation.spindle = 150;
  operation.trajectory = line(2.0);
  const size_t steps = operation.trajectory->steps();
  auto job = sender.start(operation);
  EXPECT_EQ(sender.sequencer().phase(), Phase::kOperation);
  ASSERT_TRUE(job->waitFor(kWait));
  EXPECT_EQ(job->state(), Job::State::kSucceeded) << job->message();
  EXPECT_EQ(job->sent(), steps);
  const auto commands = decodeAll(link->written());
  ASSERT_EQ(commands.size(), steps + 6);
  EXPECT_EQ(encode(commands[0]), "M1@");
  EXPECT_EQ(encode(commands[1]), "P1@");
  EXPECT_EQ(encode(commands[2]), "T2 45@");
  EXPECT_EQ(encode(commands[3]), "S150@");
  EXPECT_EQ(encode(commands[commands.size() - 2]), "#@");
  EXPECT_EQ(encode(commands.back()), "M0@");
  const auto last = std::get<Setpoint>(commands[commands.size() - 3]);
  EXPECT_EQ(last.position, (std::array<int32_t, 3>{2000, 0, 0}));
  EXPECT_EQ(job->current().position[0], 2000);
  // Back to idle, spindle stopped by M0@, and the statistics saw every setpoint.
  EXPECT_EQ(sender.sequencer().phase(), Phase::kIdle);
  EXPECT_EQ(sender.sequencer().spindle(), 0);
  EXPECT_EQ(sender.stats().setpoints, steps);
  // Intervals were measured (their values depend on the machine's load, so how many setpoints went
  // out late is not asserted here: the benchmark reports it); a stall is a run of late setpoints.
  EXPECT_GT(sender.stats().interval_max, 0.0);
  EXPECT_LE(sender.stats().stalls, sender.stats().underruns);
}

TEST_F(Fixture, AStalledWriteIsOneStallAndAnUnderrunPerSetpointDueMeanwhile)
{
  Operation operation;
  operation.trajectory = line(2.0);  // 100 setpoints
  // The 30th write blocks for 10 ms (a controller, or the machine, holding the sender up): about
  // ten setpoints come due meanwhile and go out late, back to back.
  std::atomic<int> writes{0};
  link->onWrite(
      [&](FakeTransport&, const std::vector<uint8_t>&)
      {
        if (++writes == 30)
        {
          std::this_thread::sleep_for(std::chrono::milliseconds(10));  // the stall under test
        }
      });
  auto job = sender.start(operation);
  ASSERT_TRUE(job->waitFor(kWait));
  EXPECT_EQ(job->state(), Job::State::kSucceeded) << job->message();
  const auto stats = sender.stats();
  EXPECT_EQ(stats.setpoints, operation.trajectory->steps());  // late, never skipped
  EXPECT_GE(stats.underruns, 9u);
  EXPECT_GE(stats.stalls, 1u);
  EXPECT_LT(stats.stalls, stats.underruns);  // the ten late setpoints were one stall
  EXPECT_GE(stats.max_lateness, 0.009);
}

TEST_F(Fixture, CommandsAreCheckedAndWrittenInOrder)
{
  sender.send(JogMode{Axis::kY}).get();
  sender.send(JogFeed{80}).get();
  sender.send(Home{}).get();
  const auto commands = decodeAll(link->written());
  ASSERT_EQ(commands.size(), 3u);
  EXPECT_EQ(encode(commands[0]), "JY@");
  EXPECT_EQ(encode(commands[2]), "H@");
  EXPECT_THROW(sender.send(Setpoint{}), ProtocolError);
  EXPECT_THROW(sender.send(Spindle{999}), ProtocolError);
}

TEST_F(Fixture, JogIsRefusedWhileAnOperationRunsButSpindleChangesGoBetweenSetpoints)
{
  Operation operation;
  operation.trajectory = line(200.0);  // 10 s: still running whatever the machine's load
  auto job = sender.start(operation);
  ASSERT_TRUE(link->waitForWritten(200, kWait));  // streaming
  try
  {
    sender.send(JogMode{Axis::kX});
    FAIL() << "jog accepted while machining";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_NE(std::string(e.what()).find("refused while machining"), std::string::npos);
  }
  EXPECT_THROW(sender.start(operation), ProtocolError);
  sender.send(Spindle{90}).get();
  job->cancel();
  ASSERT_TRUE(job->waitFor(kWait));
  const auto commands = decodeAll(link->written());
  size_t spindle_at = 0;
  for (size_t i = 0; i < commands.size(); ++i)
  {
    if (std::holds_alternative<Spindle>(commands[i]))
    {
      spindle_at = i;
    }
  }
  ASSERT_GT(spindle_at, 2u);
  EXPECT_TRUE(std::holds_alternative<Setpoint>(commands[spindle_at - 1]));
  EXPECT_TRUE(std::holds_alternative<Setpoint>(commands[spindle_at + 1]));
}

TEST_F(Fixture, CancelDeceleratesThenEndsTheOperation)
{
  Operation operation;
  operation.trajectory = line(500.0, 40.0);  // 12.5 s: cancelled long before the end
  auto job = sender.start(operation);
  ASSERT_TRUE(link->waitForWritten(6000, kWait));  // some 300 setpoints: at cruise speed
  job->cancel();
  ASSERT_TRUE(job->waitFor(kWait));
  EXPECT_EQ(job->state(), Job::State::kCancelled);
  const auto commands = decodeAll(link->written());
  EXPECT_EQ(encode(commands.back()), "M0@");
  std::vector<Setpoint> setpoints;
  for (const auto& c : commands)
  {
    if (const auto* s = std::get_if<Setpoint>(&c))
    {
      setpoints.push_back(*s);
    }
  }
  EXPECT_LT(setpoints.size(), operation.trajectory->steps());
  EXPECT_EQ(setpoints.back().feed[0], 0);
  EXPECT_LT(setpoints.back().position[0], 500000);
  // Never a jump: 40 mm/s is 40 pulses per period.
  for (size_t k = 1; k < setpoints.size(); ++k)
  {
    ASSERT_LE(std::abs(setpoints[k].position[0] - setpoints[k - 1].position[0]), 41);
  }
}

TEST_F(Fixture, AbortStopsStreamingAtOnceWithTheReason)
{
  Operation operation;
  operation.trajectory = line(500.0, 40.0);
  auto job = sender.start(operation);
  ASSERT_TRUE(link->waitForWritten(1000, kWait));
  sender.abortRunning("emergency stop (E1) reported by the controller");
  ASSERT_TRUE(job->waitFor(kWait));
  EXPECT_EQ(job->state(), Job::State::kAborted);
  EXPECT_EQ(job->message(), "emergency stop (E1) reported by the controller");
  const auto commands = decodeAll(link->written());
  EXPECT_EQ(encode(commands[commands.size() - 2]), "#@");
  EXPECT_EQ(encode(commands.back()), "M0@");
  EXPECT_EQ(sender.sequencer().phase(), Phase::kIdle);
}

TEST_F(Fixture, ALinkFailureFailsTheJobAndTellsTheOwner)
{
  Operation operation;
  operation.trajectory = line(500.0);
  auto job = sender.start(operation);
  ASSERT_TRUE(link->waitForWritten(500, kWait));
  link->disconnect();
  ASSERT_TRUE(job->waitFor(kWait));
  EXPECT_EQ(job->state(), Job::State::kFailed);
  EXPECT_NE(job->message().find("closed"), std::string::npos) << job->message();
  ASSERT_EQ(link_failed.get_future().wait_for(kWait), std::future_status::ready);
  EXPECT_FALSE(sender.linkUp());
  EXPECT_THROW(sender.send(AutoMode{}), LinkError);
  EXPECT_THROW(sender.start(operation), LinkError);
}
