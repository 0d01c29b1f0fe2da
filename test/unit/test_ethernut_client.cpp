// State-machine tests of the ethernut client against a scripted board (FakeTransport answering
// each written message per Table 1, with per-test deviations), one test per opcode row or flow,
// plus the client against the simulated board (board.h) over a real TCP loopback connection.
#include <gtest/gtest.h>

#include <atomic>
#include <condition_variable>
#include <fstream>
#include <functional>
#include <mutex>
#include <thread>

#include "cnc_bridge/ethernut/client.h"
#include "cnc_bridge/transport/tcp.h"
#include "sim/ethernut/board.h"
#include "temp_dir.h"
#include "testing/fake_transport.h"

using namespace cnc_bridge;
using namespace cnc_bridge::ethernut;
using std::chrono::milliseconds;

namespace
{
constexpr milliseconds kWait(5000);  // generous upper bound for a condition; tests finish far sooner

std::vector<uint8_t> bytesOf(const Message& m)
{
  const Frame f = encode(m);
  return std::vector<uint8_t>(f.begin(), f.end());
}

// Records listener events; tests wait on them.
class Recorder : public ClientListener
{
 public:
  void onState(SessionState state, SessionState) override
  {
    record([&] { states.push_back(state); });
  }
  void onPosition(float x, float y, float z) override
  {
    record([&] { positions.push_back({x, y, z}); });
  }
  void onCoordinateDone(uint64_t index, const Coordinate& c) override
  {
    record([&] { done.push_back({index, c.x}); });
  }
  void onResend(uint64_t index, unsigned count) override
  {
    record([&] { resends.push_back({index, count}); });
  }
  void onJobFinished(JobOutcome outcome, const std::string& message) override
  {
    record(
        [&]
        {
          outcomes.push_back(outcome);
          messages.push_back(message);
        });
  }
  void onBoardError(float code) override
  {
    record([&] { errors.push_back(code); });
  }

  // Waits for \p condition: woken by every event, and re-checked every few ms for conditions on
  // client state that no event announces (mode, counters).
  bool waitFor(const std::function<bool()>& condition, milliseconds timeout = kWait)
  {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    std::unique_lock<std::mutex> lock(mutex);
    while (!condition())
    {
      if (std::chrono::steady_clock::now() >= deadline)
      {
        return false;
      }
      cv.wait_for(lock, milliseconds(2));
    }
    return true;
  }
  template <typename F>
  void record(F f)
  {
    std::lock_guard<std::mutex> lock(mutex);
    f();
    cv.notify_all();
  }

  std::mutex mutex;
  std::condition_variable cv;
  std::vector<SessionState> states;
  std::vector<std::array<float, 3>> positions;
  std::vector<std::pair<uint64_t, float>> done;
  std::vector<std::pair<uint64_t, unsigned>> resends;
  std::vector<JobOutcome> outcomes;
  std::vector<std::string> messages;
  std::vector<float> errors;
};

// A board answering per Table 1; `rule` may override the answer to any message (return true when
// it handled the message).
class ScriptedBoard
{
 public:
  explicit ScriptedBoard(FakeTransport& link) : link_(link)
  {
    link_.onWrite([this](FakeTransport& t, const std::vector<uint8_t>& bytes) { onWrite(t, bytes); });
  }
  std::function<bool(const Message&, FakeTransport&)> rule;
  std::atomic<bool> answer_alive{true};
  std::atomic<bool> answer_anything{true};

  std::vector<Opcode> received()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return received_;
  }
  std::vector<Message> coordinates()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return coordinates_;
  }
  size_t count(Opcode op)
  {
    const auto r = received();
    return std::count(r.begin(), r.end(), op);
  }

 private:
  void onWrite(FakeTransport& t, const std::vector<uint8_t>& bytes)
  {
    ASSERT_EQ(bytes.size() % kMessageSize, 0u) << "the client wrote a partial message";
    for (size_t at = 0; at < bytes.size(); at += kMessageSize)
    {
      const Message m = decode(bytes.data() + at);
      const Opcode op = classify(m);
      {
        std::lock_guard<std::mutex> lock(mutex_);
        received_.push_back(op);
        if (op == Opcode::kCoordinates)
        {
          coordinates_.push_back(m);
        }
      }
      if (!answer_anything)
      {
        continue;
      }
      if (rule && rule(m, t))
      {
        continue;
      }
      switch (op)
      {
        case Opcode::kCoordinates:
          t.feed(bytesOf(makeMessage(Opcode::kNext)));
          break;
        case Opcode::kPauseRequest:
          t.feed(bytesOf(makeMessage(Opcode::kPauseAchieved)));
          break;
        case Opcode::kAliveRequest:
          if (answer_alive)
          {
            t.feed(bytesOf(makeMessage(Opcode::kAliveResponse)));
          }
          break;
        case Opcode::kAck:
        case Opcode::kAliveResponse:
          break;
        default:
          t.feed(bytesOf(makeMessage(Opcode::kAck)));
          break;
      }
    }
  }

  FakeTransport& link_;
  std::mutex mutex_;
  std::vector<Opcode> received_;
  std::vector<Message> coordinates_;
};

// Runs a client on its own thread over a scripted board.
struct Session
{
  explicit Session(ClientOptions options = ClientOptions()) : board(link)
  {
    client = std::make_unique<Client>(link, options, &recorder);
  }
  ~Session()
  {
    client->stop();
    if (thread.joinable())
    {
      thread.join();
    }
  }
  void start()
  {
    thread = std::thread(
        [this]
        {
          try
          {
            client->run();
          }
          catch (const Error& e)
          {
            std::lock_guard<std::mutex> lock(recorder.mutex);
            failure = e.what();
            recorder.cv.notify_all();
          }
          finished = true;
          recorder.record([] {});
        });
  }
  bool waitConnected()
  {
    return recorder.waitFor([&] { return client->mode() == BoardMode::kFile; });
  }
  static std::function<bool(Coordinate&)> points(std::vector<float> xs)
  {
    auto i = std::make_shared<size_t>(0);
    return [xs, i](Coordinate& c)
    {
      if (*i >= xs.size())
      {
        return false;
      }
      c.x = xs[*i];
      c.y = 0;
      c.z = 0;
      c.tag = static_cast<uint32_t>(*i);
      ++*i;
      return true;
    };
  }

  FakeTransport link{"board:6666"};
  ScriptedBoard board;
  Recorder recorder;
  std::unique_ptr<Client> client;
  std::thread thread;
  std::atomic<bool> finished{false};
  std::string failure;
};
}  // namespace

TEST(EthernutClient, HandshakeSendsInitThenFileMode)  // rows 15, 16, 5
{
  Session s;
  s.start();
  ASSERT_TRUE(s.waitConnected());
  const auto r = s.board.received();
  ASSERT_GE(r.size(), 2u);
  EXPECT_EQ(r[0], Opcode::kInitRequest);
  EXPECT_EQ(r[1], Opcode::kFileMode);
  EXPECT_EQ(s.client->state(), SessionState::kConnected);
}

TEST(EthernutClient, InitWithoutAckIsALinkError)
{
  ClientOptions o;
  o.reply_timeout = milliseconds(100);
  Session s(o);
  s.board.answer_anything = false;
  s.start();
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.finished.load(); }));
  EXPECT_NE(s.failure.find("init-request not answered"), std::string::npos) << s.failure;
}

// The handshake ends with the mode's acknowledge: until then the session is not connected (a
// job would be refused for want of file mode), and a mode never acknowledged is a link error.
TEST(EthernutClient, HandshakeEndsOnlyWhenTheModeIsAcknowledged)
{
  ClientOptions o;
  o.reply_timeout = milliseconds(100);
  Session s(o);
  s.board.rule = [](const Message& m, FakeTransport&) { return classify(m) == Opcode::kFileMode; };
  s.start();
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.board.count(Opcode::kFileMode) == 1; }));
  EXPECT_EQ(s.client->state(), SessionState::kInitialising);
  EXPECT_THROW(s.client->startJob(Session::points({1})), LinkError);
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.finished.load(); }));
  EXPECT_NE(s.failure.find("file-mode not answered"), std::string::npos) << s.failure;
  EXPECT_EQ(std::count(s.recorder.states.begin(), s.recorder.states.end(), SessionState::kConnected), 0);
}

TEST(EthernutClient, JobStreamsCoordinatesInOrderWithResend)  // rows 13, 1, 12, 14
{
  Session s;
  int coordinates_seen = 0;
  s.board.rule = [&](const Message& m, FakeTransport& t)
  {
    if (classify(m) == Opcode::kCoordinates && ++coordinates_seen == 2)
    {
      t.feed(bytesOf(makeMessage(Opcode::kResend)));  // the second set arrives damaged once
      return true;
    }
    return false;
  };
  s.start();
  ASSERT_TRUE(s.waitConnected());
  s.client->startJob(Session::points({10, 20, 30}));
  ASSERT_TRUE(s.recorder.waitFor([&] { return !s.recorder.outcomes.empty(); }));
  EXPECT_EQ(s.recorder.outcomes[0], JobOutcome::kCompleted);
  const auto sent = s.board.coordinates();
  ASSERT_EQ(sent.size(), 4u);
  EXPECT_EQ(sent[0].x, 10);
  EXPECT_EQ(sent[1].x, 20);
  EXPECT_EQ(sent[2].x, 20);  // the same set again after RESEND
  EXPECT_EQ(sent[3].x, 30);
  ASSERT_EQ(s.recorder.done.size(), 3u);
  EXPECT_EQ(s.recorder.done[2], (std::pair<uint64_t, float>{2, 30}));
  ASSERT_EQ(s.recorder.resends.size(), 1u);
  EXPECT_EQ(s.recorder.resends[0], (std::pair<uint64_t, unsigned>{1, 1}));
  const auto r = s.board.received();
  EXPECT_EQ(r[2], Opcode::kReadyToSend);  // READYTOSEND before the first coordinates
  EXPECT_EQ(s.client->stats().resends, 1u);
  EXPECT_EQ(s.client->stats().coordinates_done, 3u);
  EXPECT_EQ(s.client->state(), SessionState::kReadyToSend);
}

TEST(EthernutClient, TooManyResendsFailTheJob)
{
  ClientOptions o;
  o.max_resends = 2;
  Session s(o);
  s.board.rule = [&](const Message& m, FakeTransport& t)
  {
    if (classify(m) == Opcode::kCoordinates)
    {
      t.feed(bytesOf(makeMessage(Opcode::kResend)));
      return true;
    }
    return false;
  };
  s.start();
  ASSERT_TRUE(s.waitConnected());
  s.client->startJob(Session::points({1, 2}));
  ASSERT_TRUE(s.recorder.waitFor([&] { return !s.recorder.outcomes.empty(); }));
  EXPECT_EQ(s.recorder.outcomes[0], JobOutcome::kFailed);
  EXPECT_NE(s.recorder.messages[0].find("rejected by the board 3 times"), std::string::npos);
  EXPECT_EQ(s.board.coordinates().size(), 3u);  // first try + 2 resends
  EXPECT_FALSE(s.client->jobActive());
}

TEST(EthernutClient, BareAckAfterCoordinatesCountsAsNext)  // row 1's listed response (16)
{
  Session s;
  s.board.rule = [&](const Message& m, FakeTransport& t)
  {
    if (classify(m) == Opcode::kCoordinates)
    {
      t.feed(bytesOf(makeMessage(Opcode::kAck)));
      return true;
    }
    return false;
  };
  s.start();
  ASSERT_TRUE(s.waitConnected());
  s.client->startJob(Session::points({1, 2, 3}));
  ASSERT_TRUE(s.recorder.waitFor([&] { return !s.recorder.outcomes.empty(); }));
  EXPECT_EQ(s.recorder.outcomes[0], JobOutcome::kCompleted);
  EXPECT_EQ(s.recorder.done.size(), 3u);
}

TEST(EthernutClient, PauseHoldsTheJobAndResumeReturnsToThePreviousState)  // rows 10, 11, 13
{
  Session s;
  // The board holds the answer to the second set until it is resumed, like a move in progress.
  std::atomic<int> seen{0};
  s.board.rule = [&](const Message& m, FakeTransport& t)
  {
    if (classify(m) == Opcode::kCoordinates && ++seen == 2)
    {
      return true;  // no answer yet: the move is "running"
    }
    if (classify(m) == Opcode::kReadyToSend && seen >= 2)
    {
      t.feed(bytesOf(makeMessage(Opcode::kAck)));
      t.feed(bytesOf(makeMessage(Opcode::kNext)));  // the held move completes after resume
      return true;
    }
    return false;
  };
  s.start();
  ASSERT_TRUE(s.waitConnected());
  s.client->startJob(Session::points({1, 2, 3}));
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.client->state() == SessionState::kSending && seen == 2; }));
  s.client->pause();
  EXPECT_EQ(s.client->state(), SessionState::kPaused);
  EXPECT_THROW(s.client->startJob(Session::points({9})), ProtocolError);
  EXPECT_EQ(s.board.count(Opcode::kPauseRequest), 1u);
  s.client->pause();  // already paused: nothing sent
  EXPECT_EQ(s.board.count(Opcode::kPauseRequest), 1u);
  s.client->resume();
  ASSERT_TRUE(s.recorder.waitFor([&] { return !s.recorder.outcomes.empty(); }));
  EXPECT_EQ(s.recorder.outcomes[0], JobOutcome::kCompleted);
  EXPECT_EQ(s.board.coordinates().size(), 3u);
  // The states went ... sending -> paused -> sending (the state before the pause).
  const auto& st = s.recorder.states;
  auto paused = std::find(st.begin(), st.end(), SessionState::kPaused);
  ASSERT_NE(paused, st.end());
  ASSERT_NE(paused + 1, st.end());
  EXPECT_EQ(*(paused + 1), SessionState::kSending);
  EXPECT_THROW(s.client->resume(), ProtocolError);  // not paused any more
}

TEST(EthernutClient, PauseAchievedFromTheBoardPausesToo)  // row 11 unasked
{
  Session s;
  s.start();
  ASSERT_TRUE(s.waitConnected());
  s.link.feed(bytesOf(makeMessage(Opcode::kPauseAchieved)));
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.client->state() == SessionState::kPaused; }));
  s.client->resume();
  EXPECT_EQ(s.client->state(), SessionState::kConnected);
}

TEST(EthernutClient, ResetCancelsTheJob)  // row 8
{
  Session s;
  std::atomic<int> seen{0};
  s.board.rule = [&](const Message& m, FakeTransport&)
  {
    return classify(m) == Opcode::kCoordinates && ++seen == 1;  // hold the first move
  };
  s.start();
  ASSERT_TRUE(s.waitConnected());
  s.client->startJob(Session::points({1, 2}));
  ASSERT_TRUE(s.recorder.waitFor([&] { return seen == 1; }));
  s.client->reset();
  ASSERT_TRUE(s.recorder.waitFor([&] { return !s.recorder.outcomes.empty(); }));
  EXPECT_EQ(s.recorder.outcomes[0], JobOutcome::kCancelled);
  EXPECT_EQ(s.recorder.messages[0], "board reset");
  EXPECT_EQ(s.client->state(), SessionState::kConnected);
  EXPECT_EQ(s.board.count(Opcode::kReset), 1u);
}

TEST(EthernutClient, KillIsRefusedUnlessEnabled)  // row 9
{
  Session s;
  s.start();
  ASSERT_TRUE(s.waitConnected());
  try
  {
    s.client->kill();
    FAIL() << "kill accepted";
  }
  catch (const DisabledError& e)
  {
    EXPECT_NE(std::string(e.what()).find("enable_kill"), std::string::npos);
  }
  EXPECT_EQ(s.board.count(Opcode::kKill), 0u);

  ClientOptions o;
  o.kill_enabled = true;
  Session enabled(o);
  enabled.start();
  ASSERT_TRUE(enabled.waitConnected());
  enabled.client->kill();
  ASSERT_TRUE(enabled.recorder.waitFor([&] { return enabled.finished.load(); }));
  EXPECT_TRUE(enabled.failure.empty()) << enabled.failure;
  EXPECT_EQ(enabled.client->state(), SessionState::kKilled);
  EXPECT_EQ(enabled.board.count(Opcode::kKill), 1u);
  EXPECT_THROW(enabled.client->reset(), LinkError);  // the session is over
}

TEST(EthernutClient, ModeSwitches)  // rows 6, 7, 5
{
  Session s;
  s.start();
  ASSERT_TRUE(s.waitConnected());
  s.client->setMode(BoardMode::kGuiControl);
  EXPECT_EQ(s.client->mode(), BoardMode::kGuiControl);
  EXPECT_THROW(s.client->startJob(Session::points({1})), ProtocolError);  // jobs need file mode
  s.client->setMode(BoardMode::kFile);
  EXPECT_EQ(s.client->mode(), BoardMode::kFile);
  s.client->setMode(BoardMode::kStandalone);
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.finished.load(); }));
  EXPECT_EQ(s.client->state(), SessionState::kStandalone);
  const auto r = s.board.received();
  EXPECT_EQ(std::count(r.begin(), r.end(), Opcode::kGuiControlMode), 1);
  EXPECT_EQ(std::count(r.begin(), r.end(), Opcode::kStandaloneMode), 1);
}

TEST(EthernutClient, SyncOledAndCommandAreAcknowledged)  // rows 2, 3
{
  Session s;
  s.start();
  ASSERT_TRUE(s.waitConnected());
  s.client->syncOled(1, 2, 3);
  s.client->sendCommand(4, 5, 6);
  EXPECT_EQ(s.board.count(Opcode::kSyncOled), 1u);
  EXPECT_EQ(s.board.count(Opcode::kCommand), 1u);
}

TEST(EthernutClient, PositionReportsAreForwardedAndAcknowledged)  // row 4
{
  Session s;
  s.start();
  ASSERT_TRUE(s.waitConnected());
  Message report = makeMessage(Opcode::kPosition, 1.25f, -3.5f, 7.0f);
  report.error = 2.0f;
  s.link.feed(bytesOf(report));
  ASSERT_TRUE(s.recorder.waitFor([&] { return !s.recorder.positions.empty(); }));
  EXPECT_EQ(s.recorder.positions[0], (std::array<float, 3>{1.25f, -3.5f, 7.0f}));
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.board.count(Opcode::kAck) == 1; }));
  EXPECT_EQ(s.recorder.errors, std::vector<float>{2.0f});
  EXPECT_EQ(s.client->stats().last_board_error, 2.0f);
}

TEST(EthernutClient, KeepaliveKeepsAQuietLinkUp)  // rows 17, 18
{
  ClientOptions o;
  o.keepalive_period = milliseconds(20);
  o.dead_link_timeout = milliseconds(400);  // wide enough for a loaded machine's scheduling
  Session s(o);
  s.start();
  ASSERT_TRUE(s.waitConnected());
  // Wait for enough alive round trips (>= 1 s) to outlast the dead-link timeout.
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.client->stats().keepalive_requests >= 50; }));
  EXPECT_FALSE(s.finished.load());
  EXPECT_EQ(s.client->stats().keepalive_misses, 0u);
}

TEST(EthernutClient, SilentBoardIsADeadLinkWithinTheTimeout)
{
  ClientOptions o;
  o.keepalive_period = milliseconds(20);
  o.dead_link_timeout = milliseconds(150);
  Session s(o);
  s.start();
  ASSERT_TRUE(s.waitConnected());
  s.client->startJob(Session::points({1, 2, 3}));
  s.board.answer_anything = false;
  const auto silenced = std::chrono::steady_clock::now();
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.finished.load(); }));
  const auto detected = std::chrono::steady_clock::now() - silenced;
  EXPECT_NE(s.failure.find("silent for"), std::string::npos) << s.failure;
  EXPECT_GE(s.client->stats().keepalive_misses, 1u);
  EXPECT_LT(detected, milliseconds(150 + 1000));  // timeout plus scheduling slack
  ASSERT_FALSE(s.recorder.outcomes.empty());
  EXPECT_EQ(s.recorder.outcomes.back(), JobOutcome::kFailed);
  EXPECT_EQ(s.client->state(), SessionState::kDisconnected);
}

TEST(EthernutClient, BadFramesAreCountedAndThreeInARowDropTheLink)
{
  Session s;
  s.start();
  ASSERT_TRUE(s.waitConnected());
  std::vector<uint8_t> nan_frame = bytesOf(makeMessage(Opcode::kNext));
  nan_frame[3] = 0x7F;
  nan_frame[2] = 0xC0;  // x = NaN
  s.link.feed(nan_frame);
  s.link.feed(bytesOf(makeMessage(Opcode::kAliveResponse)));
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.client->stats().bad_frames == 1; }));
  EXPECT_FALSE(s.finished.load());
  s.link.feed(nan_frame);
  s.link.feed(nan_frame);
  s.link.feed(nan_frame);
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.finished.load(); }));
  EXPECT_NE(s.failure.find("out of step"), std::string::npos) << s.failure;
}

TEST(EthernutClient, CancelStopsStreaming)
{
  ClientOptions o;
  o.keepalive_period = milliseconds(20);  // keepalives mark the passes of the client's loop below
  o.dead_link_timeout = milliseconds(2000);
  Session s(o);
  std::atomic<int> seen{0};
  s.board.rule = [&](const Message& m, FakeTransport&)
  {
    return classify(m) == Opcode::kCoordinates && ++seen == 2;  // hold the second move
  };
  s.start();
  ASSERT_TRUE(s.waitConnected());
  s.client->startJob(Session::points({1, 2, 3, 4}));
  ASSERT_TRUE(s.recorder.waitFor([&] { return seen == 2; }));
  s.client->cancelJob();
  ASSERT_TRUE(s.recorder.waitFor([&] { return !s.recorder.outcomes.empty(); }));
  EXPECT_EQ(s.recorder.outcomes[0], JobOutcome::kCancelled);
  EXPECT_EQ(s.board.coordinates().size(), 2u);
  // A new job is accepted at once, but its first set waits for the board's answer to the held
  // one (stop-and-wait): sent earlier, the board would take it for a second set while moving.
  EXPECT_EQ(s.client->state(), SessionState::kSending);
  s.client->startJob(Session::points({5}));
  const uint64_t keepalives = s.client->stats().keepalive_requests;
  std::atomic<bool> fed{false};
  std::thread late_answer(
      [&]
      {
        // The answer comes once the client has had every chance to send too early: it has polled
        // the link and checked the new job (a keepalive request proves a pass of the loop).
        s.recorder.waitFor([&] { return s.client->stats().keepalive_requests >= keepalives + 2; });
        fed = s.board.coordinates().size() == 2u;  // nothing sent before the answer
        s.link.feed(bytesOf(makeMessage(Opcode::kNext)));
      });
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.recorder.outcomes.size() == 2; }));
  late_answer.join();
  EXPECT_TRUE(fed.load()) << "the new job's set went out before the held set was answered";
  EXPECT_EQ(s.recorder.outcomes[1], JobOutcome::kCompleted);
  ASSERT_EQ(s.board.coordinates().size(), 3u);
  EXPECT_EQ(s.board.coordinates()[2].x, 5.0f);
  EXPECT_EQ(s.client->stats().unexpected_messages, 0u);
}

TEST(EthernutClient, AliveRequestFromTheBoardIsAnswered)  // row 17 sent by the board, row 18
{
  Session s;
  s.start();
  ASSERT_TRUE(s.waitConnected());
  EXPECT_EQ(s.board.count(Opcode::kAliveResponse), 0u);
  s.link.feed(bytesOf(makeMessage(Opcode::kAliveRequest)));
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.board.count(Opcode::kAliveResponse) == 1; }));
  EXPECT_EQ(s.client->stats().unexpected_messages, 0u);
  EXPECT_FALSE(s.finished.load());
}

TEST(EthernutClient, AliveRoundTripIsMeasuredAsTheLinkRoundTrip)
{
  ClientOptions o;
  // Never silent long enough for a keepalive: only the round-trip probe sends alive requests.
  o.keepalive_period = milliseconds(3600 * 1000);
  o.dead_link_timeout = milliseconds(7200 * 1000);
  o.rtt_probe_period = milliseconds(20);
  Session s(o);
  s.start();
  ASSERT_TRUE(s.waitConnected());
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.client->stats().alive_responses >= 3; }));
  const ClientStats st = s.client->stats();
  EXPECT_GE(st.keepalive_requests, 3u);
  EXPECT_EQ(st.keepalive_misses, 0u);
  EXPECT_GE(st.last_link_rtt_ms, 0.0);
  EXPECT_LE(st.last_link_rtt_ms, st.max_link_rtt_ms);
  EXPECT_LT(st.max_link_rtt_ms, 5000.0);  // an in-memory peer answers at once
  EXPECT_EQ(st.coordinates_done, 0u);     // coordinate round trips are counted apart
}

// The board closes the connection in the middle of a job (the read fails, not a timer): the job
// ends as a lost link and run() throws LinkError.
TEST(EthernutClient, PeerClosingDuringAJobFailsTheJob)
{
  Session s;
  std::atomic<int> seen{0};
  s.board.rule = [&](const Message& m, FakeTransport&)
  {
    return classify(m) == Opcode::kCoordinates && ++seen == 2;  // hold the second move
  };
  s.start();
  ASSERT_TRUE(s.waitConnected());
  s.client->startJob(Session::points({1, 2, 3}));
  ASSERT_TRUE(s.recorder.waitFor([&] { return seen == 2; }));
  s.link.disconnect();
  ASSERT_TRUE(s.recorder.waitFor([&] { return s.finished.load() && !s.recorder.outcomes.empty(); }));
  EXPECT_EQ(s.recorder.outcomes[0], JobOutcome::kFailed);
  EXPECT_NE(s.recorder.messages[0].find("link lost"), std::string::npos) << s.recorder.messages[0];
  EXPECT_FALSE(s.failure.empty());
  EXPECT_EQ(s.client->state(), SessionState::kDisconnected);
  EXPECT_FALSE(s.client->jobActive());
}

TEST(EthernutClient, CommandsWhileDisconnectedAreRefused)
{
  FakeTransport link;
  Client client(link, ClientOptions());
  EXPECT_THROW(client.reset(), LinkError);
  EXPECT_THROW(client.startJob(Session::points({1})), LinkError);
  ClientOptions bad;
  bad.dead_link_timeout = bad.keepalive_period;
  EXPECT_THROW(Client(link, bad), ConfigError);
}

// The client against the simulated board over TCP loopback: every coordinate arrives in order
// despite a RESEND on every third one.
TEST(EthernutBoard, JobOverTcpWithInjectedResends)
{
  const test::TempDir scratch("test_ethernut_client");
  const std::string log_path = scratch.file("board_log.txt");
  BoardOptions bo;
  bo.speed_mm_per_s = 0;
  bo.resend_every = 3;
  bo.report_period = milliseconds(5);
  bo.log_path = log_path;
  Board board(bo);
  TcpServer server(0, "127.0.0.1");
  StopSignal stop;
  std::thread board_thread(
      [&]
      {
        auto peer = server.accept(kWait);
        if (peer)
        {
          board.serve(*peer, stop);
        }
      });
  auto link = TcpConnection::connect("127.0.0.1", server.port(), kWait);
  Recorder recorder;
  Client client(*link, ClientOptions(), &recorder);
  std::thread client_thread(
      [&]
      {
        try
        {
          client.run();
        }
        catch (const Error&)
        {
        }
      });
  ASSERT_TRUE(recorder.waitFor([&] { return client.mode() == BoardMode::kFile; }));
  std::vector<float> xs;
  for (int i = 0; i < 50; ++i)
  {
    xs.push_back(static_cast<float>(i) * 0.5f);
  }
  client.startJob(Session::points(xs));
  ASSERT_TRUE(recorder.waitFor([&] { return !recorder.outcomes.empty(); }));
  EXPECT_EQ(recorder.outcomes[0], JobOutcome::kCompleted) << recorder.messages[0];
  EXPECT_EQ(client.stats().resends, board.resendsSent());
  EXPECT_GE(board.resendsSent(), 10u);
  client.stop();
  client_thread.join();
  link->close();
  stop.stop();
  board_thread.join();
  std::ifstream log(log_path);
  float x, y, z;
  size_t i = 0;
  while (log >> x >> y >> z)
  {
    ASSERT_LT(i, xs.size());
    EXPECT_FLOAT_EQ(x, xs[i]) << "coordinate " << i;
    ++i;
  }
  EXPECT_EQ(i, xs.size());
}

// The simulated board stops answering alive requests (and nothing else) after two sets: once the
// job is done and the link is quiet, the client must declare it dead within the timeout.
TEST(EthernutBoard, UnansweredKeepalivesEndTheSession)
{
  BoardOptions bo;
  bo.speed_mm_per_s = 0;
  bo.report_period = milliseconds(0);
  bo.mute_keepalive_after = 2;
  Board board(bo);
  TcpServer server(0, "127.0.0.1");
  StopSignal stop;
  std::thread board_thread(
      [&]
      {
        auto peer = server.accept(kWait);
        if (peer)
        {
          board.serve(*peer, stop);
        }
      });
  auto link = TcpConnection::connect("127.0.0.1", server.port(), kWait);
  Recorder recorder;
  ClientOptions o;
  o.keepalive_period = milliseconds(30);
  o.dead_link_timeout = milliseconds(300);
  Client client(*link, o, &recorder);
  std::string failure;
  std::atomic<bool> finished{false};
  std::thread client_thread(
      [&]
      {
        try
        {
          client.run();
        }
        catch (const Error& e)
        {
          recorder.record([&] { failure = e.what(); });
        }
        finished = true;
      });
  ASSERT_TRUE(recorder.waitFor([&] { return client.mode() == BoardMode::kFile; }));
  client.startJob(Session::points({1, 2, 3}));
  ASSERT_TRUE(recorder.waitFor([&] { return !recorder.outcomes.empty(); }));
  EXPECT_EQ(recorder.outcomes[0], JobOutcome::kCompleted);
  ASSERT_TRUE(recorder.waitFor([&] { return finished.load(); }));
  EXPECT_NE(failure.find("no answer to alive requests"), std::string::npos) << failure;
  EXPECT_GE(client.stats().keepalive_misses, 1u);
  client_thread.join();
  link->close();
  stop.stop();
  board_thread.join();
}
