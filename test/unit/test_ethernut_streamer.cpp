// JobStreamer: an ethernut job streamed to the simulated board (board.h) over TCP, without ROS:
// the segments up to the program's own steps, the holds at M00/M01 until resume, a cancel while
// held (nothing more reaches the board), and a disable that holds the next segment until motion
// is enabled and resumed.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <future>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "cnc_bridge/ethernut/job_streamer.h"
#include "cnc_bridge/transport/tcp.h"
#include "sim/ethernut/board.h"

using namespace cnc_bridge;
using namespace cnc_bridge::ethernut;

namespace
{
constexpr std::chrono::milliseconds kWait(10000);  // a wait that must end ends long before this
const std::string kFixtures = CNC_BRIDGE_FIXTURE_DIR;

/// The listener a node would be: every call as a line of text, in order.
class View : public StreamListener
{
 public:
  std::atomic<bool> cancel{false};

  bool cancelRequested() override { return cancel.load(); }
  void stepDone(const gcode::ProgramStep&, const JobFeedback& f) override { add("done " + f.event); }
  void dwelling(const JobFeedback& f) override { add("dwelling " + f.event); }
  void holding(const JobFeedback& f, uint32_t line) override
  {
    add("holding " + f.event + " @" + std::to_string(line));
  }
  void resumed(const std::string& what) override { add("resumed " + what); }
  void progress(const StreamProgress& p, const JobFeedback&) override
  {
    std::lock_guard<std::mutex> lock(mutex_);
    last_progress_ = p;
  }
  void motionHoldChanged(const JobFeedback& f, bool board_holds) override
  {
    add(std::string(f.paused ? "held " : "unheld ") + (board_holds ? "(board) " : "") + f.event);
  }

  bool waitFor(const std::string& prefix)
  {
    std::unique_lock<std::mutex> lock(mutex_);
    return changed_.wait_for(lock, kWait,
                             [&] {
                               return std::any_of(calls_.begin(), calls_.end(),
                                                  [&](const std::string& c) { return c.rfind(prefix, 0) == 0; });
                             });
  }
  std::vector<std::string> calls()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return calls_;
  }
  StreamProgress lastProgress()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return last_progress_;
  }

 private:
  void add(const std::string& call)
  {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      calls_.push_back(call);
    }
    changed_.notify_all();
  }

  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<std::string> calls_;
  StreamProgress last_progress_;
};

/// The simulated board served over TCP, a client connected to it in file mode, and the streamer
/// fed the client's job events as the node feeds them.
class EthernutStreamer : public ::testing::Test, public ClientListener
{
 protected:
  EthernutStreamer()
      : board(boardOptions()),
        server(0, "127.0.0.1"),
        streamer(motion, JobRunner::Names{"/m/resume", "/m/set_motion_enabled", "/m/optional_stop"})
  {
    board_thread = std::thread(
        [this]
        {
          if (auto peer = server.accept(kWait))
          {
            board.serve(*peer, stop);
          }
        });
    link = TcpConnection::connect("127.0.0.1", server.port(), kWait);
    client = std::make_unique<Client>(*link, ClientOptions(), this);
    client_thread = std::thread(
        [this]
        {
          try
          {
            client->run();
          }
          catch (const Error&)
          {
          }
        });
  }
  ~EthernutStreamer() override
  {
    client->stop();
    client_thread.join();
    link->close();
    stop.stop();
    board_thread.join();
  }
  static BoardOptions boardOptions()
  {
    BoardOptions options;
    options.speed_mm_per_s = 0;  // every move at once
    options.report_period = std::chrono::milliseconds(0);
    return options;
  }
  void SetUp() override
  {
    // Woken by each state change, and looking again every few ms for the mode, which no event announces.
    const auto deadline = std::chrono::steady_clock::now() + kWait;
    std::unique_lock<std::mutex> lock(mutex_);
    while (client->mode() != BoardMode::kFile)
    {
      ASSERT_LT(std::chrono::steady_clock::now(), deadline) << "the board never took file mode";
      mode_cv_.wait_for(lock, std::chrono::milliseconds(5));
    }
  }

  void onState(SessionState, SessionState) override { mode_cv_.notify_all(); }
  void onCoordinateDone(uint64_t index, const Coordinate& c) override { streamer.onCoordinateDone(index, c); }
  void onResend(uint64_t, unsigned) override { streamer.onResend(); }
  void onJobFinished(JobOutcome outcome, const std::string& message) override
  {
    streamer.onJobFinished(outcome, message);
  }

  std::shared_ptr<Job> program() const
  {
    return Job::fromProgram(kFixtures + "/program_stops.nc", gcode::ParserOptions(), G53Policy(), 100);
  }

  SafetySwitch motion{SafetySwitch::Names{"motion", "/m/set_motion_enabled", "/m/enable_motion"}, true};
  Board board;
  TcpServer server;
  StopSignal stop;
  std::thread board_thread;
  std::unique_ptr<TcpConnection> link;
  std::unique_ptr<Client> client;
  std::thread client_thread;
  JobStreamer streamer;
  View view;
  std::mutex mutex_;
  std::condition_variable mode_cv_;
};
}  // namespace

// program_stops.nc: X0 (spindle, coolant), X10, M00, X20, M01, X30, G04, X40, M05 M09, M30, X99.
TEST_F(EthernutStreamer, AProgramStreamsUpToEachStopAndGoesOnAfterResume)
{
  const std::shared_ptr<Job> job = program();
  auto run = std::async(std::launch::async, [&] { return streamer.run(*client, job, view); });
  ASSERT_TRUE(view.waitFor("holding M00"));
  EXPECT_EQ(board.coordinatesAccepted(), 2u);  // X0 and X10: nothing after the stop
  EXPECT_EQ(streamer.releaseHolds(), "the M00 program stop at line 8");
  ASSERT_TRUE(view.waitFor("holding M01"));
  EXPECT_EQ(board.coordinatesAccepted(), 3u);
  streamer.releaseHolds();
  ASSERT_EQ(run.wait_for(kWait), std::future_status::ready);
  const StreamOutcome outcome = run.get();
  EXPECT_EQ(outcome.end, StreamOutcome::End::kSucceeded) << outcome.message;
  EXPECT_TRUE(outcome.program_end);
  EXPECT_EQ(outcome.message, "M30 program end at line 15: the job ends here; nothing after it was sent");
  EXPECT_EQ(outcome.done, 5u);
  EXPECT_EQ(outcome.count, 5u);
  EXPECT_EQ(board.coordinatesAccepted(), 5u);  // the move after M30 never went out
  EXPECT_EQ(view.lastProgress().done, 5u);
  const std::vector<std::string> calls = view.calls();
  const std::vector<std::string> expected = {"done spindle clockwise (M03) S8000 at line 5",
                                             "done coolant on (M07/M08) at line 6",
                                             "holding M00 program stop at line 8: waiting for /m/resume @8",
                                             "resumed M00 program stop at line 8",
                                             "holding M01 optional stop at line 10: waiting for /m/resume @10",
                                             "resumed M01 optional stop at line 10",
                                             "dwelling G04 dwell of 0.300 s at line 12",
                                             "done spindle stop (M05) S8000 at line 14",
                                             "done coolant off (M09) at line 14"};
  EXPECT_EQ(calls, expected);
}

TEST_F(EthernutStreamer, ACancelAtAProgramStopSendsNothingMore)
{
  auto run = std::async(std::launch::async, [&] { return streamer.run(*client, program(), view); });
  ASSERT_TRUE(view.waitFor("holding M00"));
  view.cancel = true;
  ASSERT_EQ(run.wait_for(kWait), std::future_status::ready);
  const StreamOutcome outcome = run.get();
  EXPECT_EQ(outcome.end, StreamOutcome::End::kCancelled);
  EXPECT_TRUE(outcome.cancelled_at_step);
  EXPECT_EQ(outcome.message, "cancelled at the M00 program stop at line 8");
  EXPECT_EQ(outcome.done, 2u);
  EXPECT_EQ(board.coordinatesAccepted(), 2u);
}

// A disable during the goal (here before its first segment) holds the job until motion is
// enabled and resumed: enabling alone sends nothing.
TEST_F(EthernutStreamer, ADisableHoldsTheNextSegmentUntilEnabledAndResumed)
{
  const JobRunner::Scope goal(streamer.runner());
  motion.set(false, "/cell");
  ASSERT_TRUE(streamer.runner().holdOnDisable("motion disabled by /cell"));
  const std::shared_ptr<Job> job = Job::fromPoints({Coordinate{1, 2, 3, 0}, Coordinate{4, 5, 6, 0}}, 100);
  auto run = std::async(std::launch::async, [&] { return streamer.run(*client, job, view); });
  ASSERT_TRUE(view.waitFor("held "));
  EXPECT_EQ(view.calls()[0],
            "held motion disabled by /cell: the job holds before its next move; enable motion with "
            "/m/set_motion_enabled (std_srvs/SetBool, data: true), then call /m/resume");
  motion.set(true, "/cell");
  EXPECT_EQ(run.wait_for(std::chrono::milliseconds(100)), std::future_status::timeout);  // held all the same
  EXPECT_EQ(board.coordinatesAccepted(), 0u);
  EXPECT_EQ(streamer.releaseHolds(), "the hold (motion disabled by /cell)");
  ASSERT_EQ(run.wait_for(kWait), std::future_status::ready);
  const StreamOutcome outcome = run.get();
  EXPECT_EQ(outcome.end, StreamOutcome::End::kSucceeded) << outcome.message;
  EXPECT_EQ(board.coordinatesAccepted(), 2u);
  EXPECT_EQ(view.calls().back(), "unheld resumed after the hold (motion disabled by /cell)");
}
