// The follower against the reference agent's recorded answers, replayed byte for byte over
// in-memory connections: sequence continuity over a stream, polling, a buffer overrun (streaming
// and polled), an agent restart, a refused stream, an agent that vanishes or answers garbage.
#include <gtest/gtest.h>

#include <deque>
#include <regex>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mtconnect/follower.h"
#include "mtconnect_fixtures.h"
#include "testing/fake_transport.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mtconnect;
using cnc_bridge::mtconnect::testing::fixture;

namespace
{
/// One request the agent expects (its target must start with \p target) and the recorded bytes it answers.
struct Step
{
  std::string target;
  std::string answer;  // bytes
};

/// An agent made of recorded answers: each connection takes the next step's request, answers it
/// and closes (as the reference agent does). Past the last step it refuses connections.
class ScriptedAgent
{
 public:
  explicit ScriptedAgent(std::deque<Step> steps) : steps_(std::move(steps)) {}

  std::unique_ptr<Transport> connect()
  {
    if (steps_.empty())
      throw LinkError("scripted agent: connection refused (script done)");
    auto link = std::make_unique<FakeTransport>("agent");
    Step step = steps_.front();
    steps_.pop_front();
    link->onWrite(
        [this, step](FakeTransport& t, const std::vector<uint8_t>& bytes)
        {
          const std::string request(bytes.begin(), bytes.end());
          const auto line_end = request.find(' ', 4);
          const std::string target = request.substr(4, line_end - 4);
          requests.push_back(target);
          if (target.rfind(step.target, 0) != 0)
            mismatches.push_back("asked " + target + ", the recording answers " + step.target);
          t.feed(step.answer);
          t.disconnect();
        });
    return link;
  }
  size_t left() const { return steps_.size(); }

  std::vector<std::string> requests;
  std::vector<std::string> mismatches;

 private:
  std::deque<Step> steps_;
};

/// The request each fixture answered (recording.json), so that a script replays the conversation.
std::string requestOf(const std::string& file)
{
  const std::string index = fixture("recording.json");
  const std::regex entry("\"file\": \"" + file + "\",\\s*\"request\": \"GET ([^\"]+)\"");
  std::smatch m;
  if (!std::regex_search(index, m, entry))
    throw std::runtime_error("recording.json has no " + file);
  return m[1];
}

Step step(const std::string& name)
{
  return {requestOf(name + ".http"), fixture(name + ".http")};
}

struct Recorder : FollowerListener
{
  void onProbe(const Document& probe, const Device& device) override
  {
    probes.push_back(probe.header.instance_id);
    device_name = device.name;
  }
  void onObservations(const std::vector<Observation>& o, bool snapshot) override
  {
    batches.push_back({o, snapshot});
    for (const auto& x : o)
    {
      if (!snapshot)
        sequences.push_back(x.sequence);
    }
  }
  void onDiscontinuity(const std::string& what) override { discontinuities.push_back(what); }

  std::vector<std::string> probes;
  std::string device_name;
  std::vector<std::pair<std::vector<Observation>, bool>> batches;
  std::vector<uint64_t> sequences;
  std::vector<std::string> discontinuities;
};

FollowerSettings streaming()
{
  FollowerSettings s;
  s.count = 8;
  s.interval = Milliseconds(100);
  s.heartbeat = Milliseconds(500);
  s.request_timeout = Milliseconds(2000);
  return s;
}

FollowerSettings polling()
{
  FollowerSettings s = streaming();
  s.streaming = false;
  s.poll_period = Milliseconds(1);
  return s;
}

/// Runs the follower through the script: probe, then follow until the script is used up (the
/// next connection is refused: LinkError). \returns that error's text.
std::string runScript(Follower& follower, ScriptedAgent&)
{
  StopSignal stop;
  try
  {
    follower.probe();
    follower.follow(stop);
  }
  catch (const LinkError& e)
  {
    return e.what();
  }
  ADD_FAILURE() << "the follower returned without the link failing";
  return "";
}

uint64_t headerValue(const std::string& name, const char* attribute)
{
  const std::regex re(std::string(attribute) + "=\"([0-9]+)\"");
  std::smatch m;
  const std::string bytes = fixture(name + ".http");
  if (!std::regex_search(bytes, m, re))
    throw std::runtime_error(name + " has no " + attribute);
  return std::stoull(m[1]);
}
}  // namespace

TEST(MtconnectFollower, StreamKeepsSequenceContinuity)
{
  ScriptedAgent agent({step("probe"), step("current"), step("stream")});
  HttpClient http("agent", [&] { return agent.connect(); });
  Recorder rec;
  Follower follower(streaming(), http, rec);
  const std::string end = runScript(follower, agent);
  EXPECT_TRUE(agent.mismatches.empty()) << agent.mismatches.front();
  EXPECT_EQ(agent.left(), 0u);
  EXPECT_EQ(rec.device_name, "mill");
  // The stream was cut when it was recorded (no last chunk): the agent vanished mid-stream.
  EXPECT_NE(end.find("middle"), std::string::npos) << end;
  ASSERT_GT(rec.sequences.size(), 20u);
  // Every sequence from /current's nextSequence on, once, in order: no gap, no repeat.
  const uint64_t first = headerValue("current", "nextSequence");
  EXPECT_EQ(rec.sequences.front(), first);
  for (size_t i = 1; i < rec.sequences.size(); ++i)
    ASSERT_EQ(rec.sequences[i], rec.sequences[i - 1] + 1) << "at " << i;
  const auto stats = follower.stats();
  EXPECT_EQ(stats.gaps, 0u);
  EXPECT_EQ(stats.restarts, 0u);
  EXPECT_EQ(stats.streams, 1u);
  EXPECT_EQ(stats.next_sequence, rec.sequences.back() + 1);
}

TEST(MtconnectFollower, PollingKeepsSequenceContinuity)
{
  ScriptedAgent agent({step("probe"), step("current"), step("sample"), step("sample_next")});
  HttpClient http("agent", [&] { return agent.connect(); });
  Recorder rec;
  Follower follower(polling(), http, rec);
  runScript(follower, agent);
  EXPECT_TRUE(agent.mismatches.empty()) << agent.mismatches.front();
  ASSERT_EQ(rec.sequences.size(), 16u);
  EXPECT_EQ(rec.sequences.front(), headerValue("current", "nextSequence"));
  for (size_t i = 1; i < rec.sequences.size(); ++i)
    EXPECT_EQ(rec.sequences[i], rec.sequences[i - 1] + 1);
  EXPECT_EQ(follower.stats().polls, 3u);  // the third found the script done
}

TEST(MtconnectFollower, StreamingOverrunIsAGapRecoveredWithCurrent)
{
  ScriptedAgent agent(
      {step("probe"), step("current_before_overrun"), step("stream_overrun"), step("current_after_overrun")});
  HttpClient http("agent", [&] { return agent.connect(); });
  Recorder rec;
  Follower follower(streaming(), http, rec);
  runScript(follower, agent);
  EXPECT_TRUE(agent.mismatches.empty()) << agent.mismatches.front();
  const auto stats = follower.stats();
  EXPECT_EQ(stats.gaps, 1u);
  EXPECT_EQ(stats.resyncs, 1u);
  const uint64_t asked = headerValue("current_before_overrun", "nextSequence");
  const uint64_t first = headerValue("stream_overrun", "firstSequence");
  ASSERT_GT(first, asked);
  EXPECT_EQ(stats.lost_observations, first - asked);
  ASSERT_EQ(rec.discontinuities.size(), 1u);
  EXPECT_NE(rec.discontinuities[0].find("buffer overrun"), std::string::npos);
  // Nothing of the overrun stream was delivered as a change; /current was delivered twice.
  EXPECT_TRUE(rec.sequences.empty());
  ASSERT_EQ(rec.batches.size(), 2u);
  EXPECT_TRUE(rec.batches[1].second);
  EXPECT_EQ(stats.next_sequence, headerValue("current_after_overrun", "nextSequence"));
}

TEST(MtconnectFollower, PolledOutOfRangeIsAGapRecoveredWithCurrent)
{
  ScriptedAgent agent(
      {step("probe"), step("current_before_overrun"), step("sample_out_of_range"), step("current_after_overrun")});
  HttpClient http("agent", [&] { return agent.connect(); });
  Recorder rec;
  Follower follower(polling(), http, rec);
  runScript(follower, agent);
  EXPECT_TRUE(agent.mismatches.empty()) << agent.mismatches.front();
  EXPECT_EQ(follower.stats().gaps, 1u);
  ASSERT_EQ(rec.discontinuities.size(), 1u);
  EXPECT_NE(rec.discontinuities[0].find("OUT_OF_RANGE"), std::string::npos) << rec.discontinuities[0];
  EXPECT_EQ(follower.stats().next_sequence, headerValue("current_after_overrun", "nextSequence"));
}

TEST(MtconnectFollower, AgentRestartIsDetectedOnReconnect)
{
  ScriptedAgent agent({step("probe"), step("current_after_overrun"), step("stream_agent_stopped"),
                       step("probe_after_restart"), step("current_after_restart"), step("stream_after_restart")});
  HttpClient http("agent", [&] { return agent.connect(); });
  Recorder rec;
  Follower follower(streaming(), http, rec);
  StopSignal stop;
  follower.probe();
  // The agent stops mid-stream: the link fails (a node's link then reconnects and probes).
  EXPECT_THROW(follower.follow(stop), LinkError);
  EXPECT_EQ(follower.stats().restarts, 0u);
  const std::string end = runScript(follower, agent);
  EXPECT_TRUE(agent.mismatches.empty()) << agent.mismatches.front();
  EXPECT_EQ(agent.left(), 0u);
  const auto stats = follower.stats();
  EXPECT_EQ(stats.restarts, 1u);
  ASSERT_EQ(rec.probes.size(), 2u);
  EXPECT_NE(rec.probes[0], rec.probes[1]);
  EXPECT_EQ(stats.instance_id, rec.probes[1]);
  EXPECT_NE(stats.last_restart.find(rec.probes[1]), std::string::npos);
  // After the restart the sequence starts again, from the new /current's nextSequence.
  ASSERT_FALSE(rec.batches.back().second);
  ASSERT_FALSE(rec.batches.back().first.empty());
  EXPECT_EQ(rec.batches.back().first.front().sequence, headerValue("current_after_restart", "nextSequence"));
}

TEST(MtconnectFollower, RestartSeenInAStreamHeaderReprobes)
{
  // The first agent's probe and /current, then the new instance's stream answers: its header
  // carries the new instanceId, so the follower probes again before reading /current.
  ScriptedAgent agent({step("probe"), step("current_after_overrun"), step("stream_after_restart"),
                       step("probe_after_restart"), step("current_after_restart")});
  HttpClient http("agent", [&] { return agent.connect(); });
  Recorder rec;
  Follower follower(streaming(), http, rec);
  runScript(follower, agent);
  EXPECT_EQ(follower.stats().restarts, 1u);
  EXPECT_EQ(follower.stats().resyncs, 1u);
  ASSERT_EQ(rec.probes.size(), 2u);
  EXPECT_NE(rec.probes[0], rec.probes[1]);
  ASSERT_EQ(agent.requests.size(), 5u);
  EXPECT_EQ(agent.requests[3], "/probe");
}

TEST(MtconnectFollower, RefusedStreamFallsBackToPolling)
{
  // An agent that answers the streaming request with one plain document.
  Step refused = step("sample");
  refused.target = "/sample?from=" + std::to_string(headerValue("current", "nextSequence")) + "&count=8&interval=";
  ScriptedAgent agent({step("probe"), step("current"), refused, step("sample_next")});
  HttpClient http("agent", [&] { return agent.connect(); });
  Recorder rec;
  Follower follower(streaming(), http, rec);
  runScript(follower, agent);
  EXPECT_TRUE(agent.mismatches.empty()) << agent.mismatches.front();
  ASSERT_EQ(agent.requests.size(), 4u);
  EXPECT_EQ(agent.requests[3].find("interval"), std::string::npos) << agent.requests[3];
  EXPECT_EQ(rec.sequences.size(), 16u);
  EXPECT_EQ(follower.stats().streams, 1u);
  EXPECT_GE(follower.stats().polls, 1u);
}

TEST(MtconnectFollower, GarbageAndOtherErrorsAreClearErrors)
{
  {
    ScriptedAgent agent(std::deque<Step>{Step{"/probe", "HTTP/1.1 200 OK\r\nContent-Length: 11\r\n\r\nhello world"}});
    HttpClient http("agent", [&] { return agent.connect(); });
    Recorder rec;
    Follower follower(streaming(), http, rec);
    try
    {
      follower.probe();
      FAIL() << "garbage accepted";
    }
    catch (const ProtocolError& e)
    {
      EXPECT_NE(std::string(e.what()).find("not XML"), std::string::npos) << e.what();
    }
  }
  {
    // A probe cut in half by the agent going away.
    const std::string probe = fixture("probe.http");
    ScriptedAgent agent(std::deque<Step>{Step{"/probe", probe.substr(0, probe.size() / 2)}});
    HttpClient http("agent", [&] { return agent.connect(); });
    Recorder rec;
    Follower follower(streaming(), http, rec);
    EXPECT_THROW(follower.probe(), LinkError);
  }
  {
    // A probe bigger than allowed.
    ScriptedAgent agent({step("probe")});
    HttpLimits limits;
    limits.max_document_bytes = 1000;
    HttpClient http(
        "agent", [&] { return agent.connect(); }, limits);
    Recorder rec;
    Follower follower(streaming(), http, rec);
    try
    {
      follower.probe();
      FAIL() << "an oversized probe accepted";
    }
    catch (const ProtocolError& e)
    {
      EXPECT_NE(std::string(e.what()).find("max_document_bytes"), std::string::npos) << e.what();
    }
  }
  {
    // An error document that is not an overrun is an error with the agent's words.
    ScriptedAgent agent({step("probe"), step("current"), step("sample_not_found")});
    HttpClient http("agent", [&] { return agent.connect(); });
    Recorder rec;
    FollowerSettings settings = polling();
    Follower follower(settings, http, rec);
    StopSignal stop;
    follower.probe();
    try
    {
      follower.follow(stop);
      FAIL() << "an error document accepted";
    }
    catch (const ProtocolError& e)
    {
      EXPECT_NE(std::string(e.what()).find("refused"), std::string::npos) << e.what();
    }
  }
}

TEST(MtconnectFollower, WrongDeviceNamesTheDevicesThere)
{
  ScriptedAgent agent(std::deque<Step>{Step{"/lathe/probe", fixture("probe.http")}});
  HttpClient http("agent", [&] { return agent.connect(); });
  Recorder rec;
  FollowerSettings settings = streaming();
  settings.device = "lathe";
  Follower follower(settings, http, rec);
  try
  {
    follower.probe();
    FAIL() << "a missing device accepted";
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("mill"), std::string::npos) << e.what();
  }
}
