// MdcClient, WritePolicy, QueryScheduler, MdcMonitor and MdcPoller against a scripted transport:
// reply matching with another client's replies interleaved, timeouts, oversize lines, the write
// allow-list, cycle events, and polls skipped while a DNC transfer holds the serial port.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <map>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mdc/mdc_client.h"
#include "cnc_bridge/mdc/mdc_monitor.h"
#include "cnc_bridge/transport/serial_port.h"
#include "testing/fake_transport.h"
#include "testing/pty.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mdc;
using namespace std::chrono_literals;

namespace
{
std::string text(const std::vector<uint8_t>& bytes)
{
  return std::string(bytes.begin(), bytes.end());
}

// Answers each query line with the given replies, in order.
void answerWith(FakeTransport& fake, std::vector<std::string> replies)
{
  auto queue = std::make_shared<std::vector<std::string>>(std::move(replies));
  fake.onWrite(
      [queue](FakeTransport& f, const std::vector<uint8_t>&)
      {
        if (!queue->empty())
        {
          f.feed(queue->front());
          queue->erase(queue->begin());
        }
      });
}
}  // namespace

TEST(MdcClient, SendsTheQueryWithCrLf)
{
  FakeTransport fake;
  answerWith(fake, {">MODE, (MEM)\r\n"});
  MdcClient client(fake);
  const Reply reply = client.request(q(104), 1000ms);
  EXPECT_EQ(text(fake.written()), "?Q104\r\n");
  EXPECT_EQ(valueOf(reply), "(MEM)");
  EXPECT_EQ(client.stats().sent, 1u);
  EXPECT_EQ(client.stats().answered, 1u);
}

TEST(MdcClient, ForeignRepliesInterleavedAreSetAsideNotTakenForOurs)
{
  FakeTransport fake;
  // Another MDC client asked for Q100 and a macro; the control sent those replies to us too,
  // before and after ours, split across reads.
  answerWith(fake, {">SERIAL NUMBER, 1234567\r\n>MACRO, 5022, 2.0\r\n>MACRO, 5021, 1.5\r\n>MODE, (MDI)\r\n"});
  fake.setMaxReadChunk(7);
  MdcClient client(fake);
  std::vector<std::string> foreign;
  client.setForeignListener([&](const Reply& r) { foreign.push_back(r.line); });
  EXPECT_DOUBLE_EQ(client.readVariable(5021, 1000ms), 1.5);
  EXPECT_EQ(foreign, (std::vector<std::string>{"SERIAL NUMBER, 1234567", "MACRO, 5022, 2.0"}));
  // The reply after ours stays buffered and is seen on the next request.
  answerWith(fake, {">PROGRAM, O1, IDLE, PARTS, 3\r\n"});
  const Reply reply = client.request(q(500), 1000ms);
  EXPECT_EQ(toProgramStatus(reply).parts, 3);
  EXPECT_EQ(foreign.back(), "MODE, (MDI)");
  EXPECT_EQ(client.stats().foreign, 3u);
}

TEST(MdcClient, NoAnswerIsATimeoutAndCounted)
{
  FakeTransport fake;
  answerWith(fake, {">MODE, (MEM)\r\n"});  // answers the wrong question
  MdcClient client(fake);
  EXPECT_THROW(client.request(q(500), 50ms), TimeoutError);
  EXPECT_EQ(client.stats().unanswered, 1u);
  EXPECT_EQ(client.stats().foreign, 1u);
}

TEST(MdcClient, RejectedQueryIsReportedNotWaitedOut)
{
  FakeTransport fake;
  answerWith(fake, {">?, ?Q105\r\n", ">?, ?Q105\r\n"});
  MdcClient client(fake);
  EXPECT_EQ(client.request(q(105), 1000ms).kind, ReplyKind::kUnknownQuery);
  EXPECT_THROW(client.requestValue(q(105), 1000ms), ProtocolError);
  EXPECT_EQ(client.stats().rejected, 2u);
}

TEST(MdcClient, OversizeLineIsDroppedAndTheNextReplyStillArrives)
{
  FakeTransport fake;
  answerWith(fake, {">" + std::string(3 * kMaxLineLength, 'A') + "\r\n>MODE, (MEM)\r\n"});
  MdcClient client(fake);
  EXPECT_EQ(valueOf(client.request(q(104), 1000ms)), "(MEM)");
  EXPECT_EQ(client.stats().dropped_lines, 1u);
}

TEST(MdcClient, PeerVanishingIsALinkError)
{
  FakeTransport fake;
  fake.onWrite([](FakeTransport& f, const std::vector<uint8_t>&) { f.disconnect(); });
  MdcClient client(fake);
  EXPECT_THROW(client.request(q(500), 1000ms), LinkError);
}

TEST(MdcClient, WriteUsesTheECommand)
{
  FakeTransport fake;
  answerWith(fake, {">!\r\n", ">?, ?E5021\r\n"});
  MdcClient client(fake);
  client.writeVariable(100, 2.5, 1000ms);
  EXPECT_EQ(text(fake.written()), "?E100 2.5\r\n");
  EXPECT_THROW(client.writeVariable(5021, 1, 1000ms), ProtocolError);
  // A value the wire cannot carry exactly is refused before anything is written.
  const size_t written = fake.written().size();
  EXPECT_THROW(client.writeVariable(100, 1e-7, 1000ms), ProtocolError);
  EXPECT_THROW(client.writeVariable(100, 1e300, 1000ms), ProtocolError);
  EXPECT_EQ(fake.written().size(), written);
}

TEST(MdcWritePolicy, RefusalNamesTheParameter)
{
  const WritePolicy none({}, "/haas/writable_variables");
  try
  {
    none.check(100);
    FAIL();
  }
  catch (const DisabledError& e)
  {
    EXPECT_NE(std::string(e.what()).find("/haas/writable_variables"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("disabled"), std::string::npos);
  }
  const WritePolicy some({101, 100, 100}, "~writable_variables");
  EXPECT_NO_THROW(some.check(100));
  EXPECT_TRUE(some.allows(101));
  EXPECT_EQ(some.allowed().size(), 2u);
  try
  {
    some.check(5021);
    FAIL();
  }
  catch (const DisabledError& e)
  {
    EXPECT_NE(std::string(e.what()).find("#5021"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("~writable_variables"), std::string::npos);
  }
}

TEST(MdcScheduler, EachQueryAtItsOwnPeriod)
{
  QueryScheduler s;
  s.add(q(100), QueryScheduler::kOnce);
  s.add(q(500), 100ms);
  s.add(q(201), 1000ms);
  const Clock::time_point t0{};
  s.reset(t0);
  std::vector<int> order;
  auto now = t0;
  // Simulate 1 s with replies taking no time: record what is sent.
  for (;;)
  {
    const auto next = s.next();
    ASSERT_TRUE(next);
    if (next->second >= t0 + 1000ms)
      break;
    now = std::max(now, next->second);
    order.push_back(next->first.code);
    s.done(now);
  }
  EXPECT_EQ(std::count(order.begin(), order.end(), 100), 1);
  EXPECT_EQ(std::count(order.begin(), order.end(), 500), 10);
  EXPECT_EQ(std::count(order.begin(), order.end(), 201), 1);
  EXPECT_EQ(order[0], 100);  // ties go in the order added
  EXPECT_EQ(order[1], 500);
}

TEST(MdcScheduler, NoBurstAfterAStall)
{
  QueryScheduler s;
  s.add(q(500), 100ms);
  const Clock::time_point t0{};
  s.reset(t0);
  s.done(t0 + 5000ms);  // the query took 5 s (a stalled link)
  EXPECT_EQ(s.next()->second, t0 + 5000ms);
  s.done(t0 + 5000ms);
  EXPECT_EQ(s.next()->second, t0 + 5100ms);
}

TEST(MdcMonitor, CycleStartEndAndPartCount)
{
  MdcMonitor monitor;
  Clock::time_point t{};
  auto apply = [&](const std::string& line, std::chrono::milliseconds after)
  {
    t += after;
    return monitor.apply(*parseReply(line), t);
  };
  EXPECT_TRUE(apply("PROGRAM, O00110, IDLE, PARTS, 10", 0ms).empty());  // first status: no event
  auto events = apply("STATUS, BUSY", 100ms);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].type, CycleEventData::kCycleStart);
  EXPECT_EQ(events[0].program, "O00110");
  EXPECT_TRUE(apply("PROGRAM, O00110, FEED HOLD, PARTS, 10", 1000ms).empty());
  EXPECT_EQ(monitor.status().execution, Execution::kPaused);
  EXPECT_TRUE(apply("STATUS, BUSY", 500ms).empty());
  events = apply("PROGRAM, O00110, IDLE, PARTS, 11", 1500ms);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].type, CycleEventData::kCycleEnd);
  EXPECT_EQ(events[0].part_count, 11);
  EXPECT_NEAR(events[0].cycle_time, 3.0, 1e-9);
  // A cycle shorter than the poll period: only the counter shows it.
  events = apply("PROGRAM, O00110, IDLE, PARTS, 12", 100ms);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].type, CycleEventData::kPartCount);
  // Alarm during a cycle.
  apply("STATUS, BUSY", 100ms);
  events = apply("PROGRAM, O00110, ALARM, PARTS, 12", 100ms);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].type, CycleEventData::kAlarm);
  EXPECT_EQ(monitor.status().execution, Execution::kAlarm);
  EXPECT_FALSE(monitor.inCycle());
}

TEST(MdcMonitor, JoiningMidCycleReportsTheEndWithUnknownTime)
{
  MdcMonitor monitor;
  Clock::time_point t{};
  EXPECT_TRUE(monitor.apply(*parseReply("STATUS, BUSY"), t).empty());
  const auto events = monitor.apply(*parseReply("PROGRAM, O2, IDLE, PARTS, 5"), t + 1s);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].type, CycleEventData::kCycleEnd);
  EXPECT_LT(events[0].cycle_time, 0);
}

TEST(MdcMonitor, FoldsEveryReadIntoTheStatus)
{
  MdcMonitor monitor;
  const Clock::time_point t{};
  for (const char* line :
       {"SERIAL NUMBER, 1234567", "MODEL, VF2D", "SOFTWARE VERSION, 100.20", "MODE, (ZERO RET)", "USING TOOL, 7",
        "LAST CYCLE, 000:01:05", "M30 #1, 42", "MACRO, 4006, 20.0", "MACRO, 5021, -1.25", "USING TOOL, bad"})
  {
    monitor.apply(*parseReply(line), t);
  }
  const auto& s = monitor.status();
  EXPECT_EQ(s.serial_number, "1234567");
  EXPECT_EQ(s.model, "VF2D");
  EXPECT_EQ(s.mode, Mode::kHoming);
  EXPECT_EQ(s.tool, 7);  // the malformed reply did not clobber it
  EXPECT_EQ(s.last_cycle_s, 65.0);
  EXPECT_EQ(s.m30_counter1, 42);
  EXPECT_EQ(s.units, Units::kInch);
  EXPECT_EQ(s.variables.at(5021), -1.25);
  EXPECT_EQ(s.updates, 9u);
}

namespace
{
// A fake control for the poller: answers every query line from a small table.
void fakeControl(FakeTransport& fake, const std::string& status)
{
  fake.onWrite(
      [status](FakeTransport& f, const std::vector<uint8_t>& bytes)
      {
        const std::string query(bytes.begin(), bytes.end());
        if (query.rfind("?Q500", 0) == 0)
          f.feed(">" + status + "\r\n");
        else if (query.rfind("?Q104", 0) == 0)
          f.feed(">MODE, (MEM)\r\n");
        else if (query.rfind("?Q600 5021", 0) == 0)
          f.feed(">MACRO, 5021, 1.0\r\n");
        else
          f.feed(">?, " + query.substr(0, query.size() - 2) + "\r\n");
      });
}
}  // namespace

TEST(MdcPoller, PollsUntilStoppedAndCountsRejectedQueries)
{
  FakeTransport fake;
  fakeControl(fake, "PROGRAM, O7, IDLE, PARTS, 1");
  PollPlan plan;
  plan.status_period = 5ms;
  plan.variables_period = 5ms;
  plan.counters_period = 50ms;
  plan.variables = {5021};
  MdcPoller poller(plan, 500ms);
  StopSignal stop;
  std::mutex m;
  std::condition_variable cv;
  int updates = 0;
  poller.setListener(
      [&](const MachineStatus& s, const std::vector<CycleEventData>&)
      {
        std::lock_guard<std::mutex> lock(m);
        ++updates;
        cv.notify_all();
      });
  std::thread thread([&] { poller.run(fake, stop); });
  {
    std::unique_lock<std::mutex> lock(m);
    ASSERT_TRUE(cv.wait_for(lock, 5s, [&] { return updates >= 20; }));
  }
  double read = 0;
  poller.withClient([&](MdcClient& c) { read = c.readVariable(5021, 500ms); });
  EXPECT_EQ(read, 1.0);
  stop.stop();
  thread.join();
  const auto status = poller.status();
  EXPECT_EQ(status.program, "O7");
  EXPECT_EQ(status.execution, Execution::kReady);
  EXPECT_EQ(status.mode, Mode::kAuto);
  EXPECT_EQ(status.variables.at(5021), 1.0);
  // Q100..Q102 and the counters are "unknown" to this fake control: rejected, not unanswered.
  EXPECT_GE(poller.stats().rejected, 3u);
  EXPECT_EQ(poller.stats().unanswered, 0u);
  EXPECT_THROW(poller.withClient([](MdcClient&) {}), LinkError);
}

TEST(MdcPoller, SkipsPollsWhileADncTransferHoldsThePort)
{
  const std::string device = "/tmp/cnc_bridge_test_mdc_port_" + std::to_string(::getpid());
  PortLock dnc(device);
  ASSERT_TRUE(dnc.tryLock());
  PortLock mine(device);
  FakeTransport fake;
  fakeControl(fake, "STATUS, BUSY");
  PollPlan plan;
  plan.status_period = 2ms;
  plan.identity = false;
  MdcPoller poller(plan, 500ms, &mine);
  StopSignal stop;
  std::thread thread([&] { poller.run(fake, stop); });
  // Not one byte while the transfer runs (a bounded wait for a write that must not come), and
  // the poller counts the polls it skipped (once its thread has run: on a loaded machine that can
  // take longer than the wait above).
  EXPECT_FALSE(fake.waitForWritten(1, 200ms));
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (poller.skippedForPortLock() == 0 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(2ms);  // poll: a counter of another thread: nothing to wait on but itself
  EXPECT_GT(poller.skippedForPortLock(), 0u);
  EXPECT_EQ(fake.written().size(), 0u);
  EXPECT_THROW(poller.withClient([](MdcClient&) {}), LinkError);
  dnc.unlock();
  ASSERT_TRUE(fake.waitForWritten(6, 5s));
  stop.stop();
  thread.join();
  EXPECT_EQ(poller.status().execution, Execution::kActive);
}

TEST(MdcMonitor, WorkOffsetOnlyFromReadsWhileTheAxisStoodStill)
{
  MdcMonitor monitor;
  monitor.setWorkOffsetAxes({{5021, 5041}, {5022, 5042}, {5023, 5043}});
  const Clock::time_point t{};
  auto macro = [&](int n, double v)
  { monitor.apply(*parseReply("MACRO, " + std::to_string(n) + ", " + std::to_string(v)), t); };
  // X moving: machine 1.0, work -4.0 (read a little later, at machine 1.2), machine 1.5.
  macro(5021, 1.0);
  macro(5041, -3.8);
  macro(5021, 1.5);
  EXPECT_FALSE(monitor.status().work_offset[0]);
  // X standing at 1.5: the work reading between two equal machine readings gives the offset.
  macro(5041, -3.5);
  macro(5021, 1.5);
  ASSERT_TRUE(monitor.status().work_offset[0]);
  EXPECT_DOUBLE_EQ(*monitor.status().work_offset[0], 5.0);
  // Moving again: the last good offset stays.
  macro(5041, -3.0);
  macro(5021, 2.5);
  EXPECT_DOUBLE_EQ(*monitor.status().work_offset[0], 5.0);
  EXPECT_FALSE(monitor.status().work_offset[1]);
}

TEST(MdcClient, ClassicSerialLineWithSevenDataBitsAndFramedReplies)
{
  // The test is the control: it owns the pty master; the client opens the slave as a 7E1 port,
  // as on a Classic control with settings 37 = 7 and 12 = even.
  PtyMaster control;
  SerialSettings settings;
  settings.device = control.slavePath();
  settings.baud = 9600;
  settings.data_bits = 7;
  settings.parity = Parity::kEven;
  SerialPort port(settings);
  std::thread machine(
      [&]
      {
        std::string received;
        uint8_t buffer[64];
        while (received.find('\n') == std::string::npos)
        {
          const size_t n = control.read(buffer, sizeof buffer, 2000ms);
          if (n == 0)
            return;
          received.append(reinterpret_cast<const char*>(buffer), n);
        }
        if (received == "?Q500\r\n")
          control.write(std::string("\x02STATUS, BUSY\x17\r\n>"));
      });
  MdcClient client(port);
  const Reply reply = client.request(q(500), 2000ms);
  machine.join();
  EXPECT_EQ(toProgramStatus(reply).status, "BUSY");
  EXPECT_EQ(client.stats().answered, 1u);
}

TEST(MdcPoller, AControlThatStopsAnsweringEndsThePollWithALinkError)
{
  FakeTransport fake;  // a serial control switched off: writes go out, nothing comes back
  PollPlan plan;
  plan.identity = false;
  plan.status_period = 1ms;
  plan.max_unanswered = 3;
  MdcPoller poller(plan, 20ms);
  StopSignal stop;
  try
  {
    poller.run(fake, stop);
    FAIL() << "run() returned";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("3 queries in a row"), std::string::npos) << e.what();
    // What to compare: the control's MDC setting, or its serial settings.
    EXPECT_NE(std::string(e.what()).find("Setting 143"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("Settings 11, 12, 37 and 13"), std::string::npos) << e.what();
  }
  EXPECT_EQ(poller.stats().unanswered, 3u);
}

namespace
{
// A fake control whose answer to each query line is a function of the query and how often that
// query was asked before (0 for the first time); an empty answer is no reply.
using Answer = std::function<std::string(const std::string& query, int asked)>;
void scriptedControl(FakeTransport& fake, Answer answer)
{
  auto asked = std::make_shared<std::map<std::string, int>>();
  fake.onWrite(
      [answer, asked](FakeTransport& f, const std::vector<uint8_t>& bytes)
      {
        const std::string query(bytes.begin(), bytes.end() - 2);  // without CR LF
        const std::string reply = answer(query, (*asked)[query]++);
        if (!reply.empty())
          f.feed(">" + reply + "\r\n");
      });
}

// What a poller reported, with a bounded wait for a condition on it.
struct Reported
{
  std::mutex mutex;
  std::condition_variable changed;
  MachineStatus status;
  std::vector<CycleEventData> events;

  void listen(MdcPoller& poller)
  {
    poller.setListener(
        [this](const MachineStatus& s, const std::vector<CycleEventData>& e)
        {
          std::lock_guard<std::mutex> lock(mutex);
          status = s;
          events.insert(events.end(), e.begin(), e.end());
          changed.notify_all();
        });
  }
  bool waitFor(const std::function<bool()>& predicate, std::chrono::milliseconds timeout = 5s)
  {
    std::unique_lock<std::mutex> lock(mutex);
    return changed.wait_for(lock, timeout, predicate);
  }
};

PollPlan fastPlan()
{
  PollPlan plan;
  plan.identity = false;
  plan.status_period = 2ms;
  plan.variables_period = 2ms;
  plan.counters_period = 10s;
  return plan;
}
}  // namespace

TEST(MdcScheduler, AnUnansweredOnceQueryIsAskedAgainAPeriodicOneKeepsItsPeriod)
{
  QueryScheduler s;
  s.add(q(100), QueryScheduler::kOnce);
  s.add(q(500), 100ms);
  const Clock::time_point t0{};
  s.reset(t0);
  ASSERT_EQ(s.next()->first, q(100));
  s.unanswered(t0 + 10ms, 2000ms);
  ASSERT_EQ(s.next()->first, q(500));
  s.unanswered(t0 + 20ms, 2000ms);
  EXPECT_EQ(s.next()->second, t0 + 100ms);  // Q500 again one period on
  s.done(t0 + 100ms);
  s.done(t0 + 200ms);
  // ... and Q100 is still there, due 2 s after it went unanswered; answered, it is finished.
  for (int i = 0; i < 100 && s.next()->first == q(500); ++i)
    s.done(s.next()->second);
  EXPECT_EQ(s.next()->first, q(100));
  EXPECT_EQ(s.next()->second, t0 + 2010ms);
  s.done(t0 + 2010ms);
  for (int i = 0; i < 50; ++i)
  {
    EXPECT_EQ(s.next()->first, q(500));
    s.done(s.next()->second);
  }
}

TEST(MdcPollPlan, PerQueryPeriodsOverrideTheGroupsAddAndRemoveQueries)
{
  PollPlan plan;
  plan.status_period = 250ms;
  plan.variables_period = 250ms;
  plan.counters_period = 2000ms;
  plan.variables = {5021, 5022};
  plan.query_periods = {{parseQueryKey("Q500"), 100ms},
                        {parseQueryKey("Q600 5021"), 50ms},
                        {parseQueryKey("?Q300"), 60000ms},
                        {parseQueryKey("Q303"), 0ms},
                        {parseQueryKey("Q600_100"), 1000ms}};
  const auto entries = plan.scheduler().plan();
  std::map<std::string, Milliseconds> period;
  for (const auto& [query, p] : entries)
  {
    EXPECT_EQ(period.count(query.text()), 0u) << query.text() << " twice";
    period[query.text()] = p;
  }
  EXPECT_EQ(period.at("?Q500"), 100ms);
  EXPECT_EQ(period.at("?Q104"), 250ms);  // its group's period
  EXPECT_EQ(period.at("?Q600 5021"), 50ms);
  EXPECT_EQ(period.at("?Q600 5022"), 250ms);
  EXPECT_EQ(period.at("?Q300"), 60000ms);  // not in the groups: added
  EXPECT_EQ(period.at("?Q600 100"), 1000ms);
  EXPECT_EQ(period.count("?Q303"), 0u);  // 0: not polled
  EXPECT_EQ(period.at("?Q304"), 2000ms);
  EXPECT_EQ(period.at("?Q100"), QueryScheduler::kOnce);
  EXPECT_EQ(entries.front().first, q(100));  // the groups' order is kept

  // In the groups 0 is "as often as possible" (the benchmark's setting), not "never".
  PollPlan flat;
  flat.status_period = flat.variables_period = flat.counters_period = 0ms;
  flat.identity = false;
  const auto all = flat.scheduler().plan();
  ASSERT_EQ(all.size(), 7u);  // Q500, Q104, Q201, Q303, Q304, Q402, Q200
  EXPECT_EQ(all.front(), std::make_pair(q(500), Milliseconds(0)));
}

TEST(MdcPollPlan, QueryKeysMustBeReadOnlyQueries)
{
  EXPECT_EQ(parseQueryKey(" Q600 5021"), macroQuery(5021));
  EXPECT_EQ(parseQueryKey("q104"), q(104));
  EXPECT_THROW(parseQueryKey("E100 1"), ConfigError);
  EXPECT_THROW(parseQueryKey("status"), ConfigError);
  EXPECT_THROW(parseQueryKey(""), ConfigError);
}

TEST(MdcPoller, IdentityQueriesLeftUnansweredOrFirstRejectedAreAskedAgain)
{
  // The Haas NGC MDC page: "For the initial connection, ?Q100 may have to be entered twice." The
  // first ?Q100 here goes unanswered, the second is rejected, the third answered; Q102 is rejected
  // every time: asked twice (a first rejection may be the new connection's), then never again.
  FakeTransport fake;
  scriptedControl(fake,
                  [](const std::string& query, int asked) -> std::string
                  {
                    if (query == "?Q100")
                      return asked == 0 ? "" : asked == 1 ? "?, ?Q100" : "SERIAL NUMBER, 1234567";
                    if (query == "?Q101")
                      return "SOFTWARE VERSION, 100.17.000.2037";
                    if (query == "?Q102")
                      return "?, ?Q102";
                    if (query == "?Q500")
                      return "PROGRAM, O1, IDLE, PARTS, 1";
                    return "";
                  });
  PollPlan plan = fastPlan();
  plan.identity = true;
  plan.counters_period = 20ms;  // also the wait before an identity query is asked again
  plan.query_periods = {{q(104), 0ms}, {q(201), 0ms}, {q(303), 0ms}, {q(304), 0ms}, {q(402), 0ms}, {q(200), 0ms}};
  plan.max_unanswered = 0;
  MdcPoller poller(plan, 20ms);
  Reported reported;
  reported.listen(poller);
  StopSignal stop;
  std::thread thread([&] { poller.run(fake, stop); });
  auto count = [&](const std::string& sent, const std::string& what)
  {
    size_t n = 0;
    for (size_t at = sent.find(what); at != std::string::npos; at = sent.find(what, at + 1))
      ++n;
    return n;
  };
  EXPECT_TRUE(reported.waitFor([&] { return reported.status.serial_number == "1234567"; }));
  // Then 50 more status polls at 2 ms (well past the 20 ms retry wait) after the second Q102.
  EXPECT_TRUE(reported.waitFor(
      [&]
      {
        const std::string sent = text(fake.written());
        const size_t last_q102 = sent.rfind("?Q102\r\n");
        return count(sent, "?Q102\r\n") >= 2 && count(sent.substr(last_q102), "?Q500\r\n") >= 50;
      }));
  stop.stop();
  thread.join();
  const std::string sent = text(fake.written());
  EXPECT_EQ(count(sent, "?Q100\r\n"), 3u);
  EXPECT_EQ(count(sent, "?Q101\r\n"), 1u);
  EXPECT_EQ(count(sent, "?Q102\r\n"), 2u);
}

TEST(MdcMonitor, AnNgcMacroReplyCountsOnlyForTheQueryItAnswered)
{
  // "MACRO, value" names no variable: the client's match supplies it; another client's such reply
  // cannot be placed and changes nothing.
  MdcMonitor monitor;
  const Clock::time_point t0{};
  Reply foreign = *parseReply(">MACRO, 2.5");
  monitor.apply(foreign, t0);
  EXPECT_TRUE(monitor.status().variables.empty());
  Reply ours = foreign;
  ours.answered = macroQuery(5021);
  monitor.apply(ours, t0);
  ASSERT_EQ(monitor.status().variables.count(5021), 1u);
  EXPECT_EQ(monitor.status().variables.at(5021), 2.5);

  FakeTransport fake;
  answerWith(fake, {">MACRO, -0.125\r\n>"});
  MdcClient client(fake);
  EXPECT_EQ(client.readVariable(5022, 1000ms), -0.125);
}

TEST(MdcPoller, HoldsThePortLockForEachQueryAndReleasesItBetween)
{
  const std::string device = "/tmp/cnc_bridge_test_mdc_hold_" + std::to_string(::getpid());
  PortLock probe(device);
  PortLock mine(device);
  FakeTransport fake;
  std::atomic<int> written_unlocked{0}, written{0};
  // The control looks at the lock whenever a query arrives: it must be held by the poller then.
  fake.onWrite(
      [&](FakeTransport& f, const std::vector<uint8_t>&)
      {
        ++written;
        if (!probe.heldElsewhere())
          ++written_unlocked;
        f.feed(">STATUS, BUSY\r\n>MODE, (MEM)\r\n");
      });
  PollPlan plan = fastPlan();
  plan.query_periods = {{q(201), 0ms}, {q(303), 0ms}, {q(304), 0ms}, {q(402), 0ms}, {q(200), 0ms}};
  MdcPoller poller(plan, 500ms, &mine);
  StopSignal stop;
  std::thread thread([&] { poller.run(fake, stop); });
  ASSERT_TRUE(fake.waitForWritten(100, 5s));
  // Between two queries the lock is free: a transfer gets it within its patience.
  PortLock dnc(device);
  ASSERT_TRUE(dnc.lockForTransfer(2s));
  dnc.unlock();
  stop.stop();
  thread.join();
  EXPECT_GT(written.load(), 10);
  EXPECT_EQ(written_unlocked.load(), 0);
  EXPECT_FALSE(probe.heldElsewhere());
}

TEST(MdcPoller, AfterATransferUsedTheLineItsBytesAreDroppedAndTheSettingsReapplied)
{
  const std::string device = "/tmp/cnc_bridge_test_mdc_regain_" + std::to_string(::getpid());
  PortLock mine(device);
  PortLock dnc(device);
  FakeTransport fake;
  fakeControl(fake, "PROGRAM, O7, IDLE, PARTS, 1");
  PollPlan plan = fastPlan();
  MdcPoller poller(plan, 500ms, &mine);
  std::atomic<int> reapplied{0};
  poller.setPortRegainedHook([&](Transport& link) { reapplied += &link == &fake ? 1 : 100; });
  Reported reported;
  reported.listen(poller);
  StopSignal stop;
  std::thread thread([&] { poller.run(fake, stop); });
  ASSERT_TRUE(fake.waitForWritten(30, 5s));
  EXPECT_EQ(reapplied.load(), 0);  // no transfer yet
  ASSERT_TRUE(dnc.lockForTransfer(2s));
  const size_t before = fake.written().size();
  // The transfer's bytes (an XModem block with no line end) arrive while the poller is silent.
  fake.feed(std::string("\x01\x01\xfe") + std::string(128, 'G') + "\x1a");
  EXPECT_FALSE(fake.waitForWritten(before + 1, 100ms));  // not a byte from the poller meanwhile
  dnc.unlock();
  ASSERT_TRUE(fake.waitForWritten(before + 30, 5s));
  stop.stop();
  thread.join();
  EXPECT_EQ(reapplied.load(), 1);
  EXPECT_EQ(poller.portRegained(), 1u);
  EXPECT_GT(poller.skippedForPortLock(), 0u);
  // The transfer's bytes were dropped, not glued to the next reply (which would go unanswered).
  EXPECT_EQ(poller.stats().unanswered, 0u);
  EXPECT_EQ(poller.status().program, "O7");
}

namespace
{
// A control that runs one cycle: Q500 says IDLE, BUSY, BUSY, then IDLE with one more part.
std::string oneCycle(const std::string& query, int asked, const std::string& q303)
{
  if (query == "?Q500")
    return asked == 0 ? "PROGRAM, O1, IDLE, PARTS, 1" : asked < 3 ? "STATUS, BUSY" : "PROGRAM, O1, IDLE, PARTS, 2";
  if (query == "?Q303")
    return q303.empty() ? "?, ?Q303" : q303 + std::to_string(asked + 1);
  return "?, " + query;
}

std::vector<CycleEventData> runOneCycle(FakeTransport& fake, bool from_control)
{
  PollPlan plan = fastPlan();
  plan.cycle_time_from_control = from_control;
  MdcPoller poller(plan, 500ms);
  Reported reported;
  reported.listen(poller);
  StopSignal stop;
  std::thread thread([&] { poller.run(fake, stop); });
  const bool ended = reported.waitFor(
      [&]
      {
        return std::any_of(reported.events.begin(), reported.events.end(),
                           [](const CycleEventData& e) { return e.type == CycleEventData::kCycleEnd; });
      });
  stop.stop();
  thread.join();
  EXPECT_TRUE(ended);
  return reported.events;
}
}  // namespace

TEST(MdcPoller, CycleEndCarriesTheControlsLastCycleTime)
{
  FakeTransport fake;
  // LAST CYCLE is 1 s when first polled, 2 s when asked again: only a fresh ask gives 2 s.
  scriptedControl(fake,
                  [](const std::string& query, int asked) { return oneCycle(query, asked, "LAST CYCLE, 0:00:0"); });
  const auto events = runOneCycle(fake, true);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].type, CycleEventData::kCycleStart);
  EXPECT_EQ(events[1].type, CycleEventData::kCycleEnd);
  EXPECT_EQ(events[1].part_count, 2);
  EXPECT_DOUBLE_EQ(events[1].cycle_time, 2.0);
  EXPECT_NE(events[1].text.find("from the control"), std::string::npos) << events[1].text;
  // Asked right after the status that ended the cycle.
  const std::string sent = text(fake.written());
  const size_t end_status =
      sent.find("?Q500\r\n", sent.find("?Q500\r\n", sent.find("?Q500\r\n", sent.find("?Q500\r\n") + 1) + 1) + 1);
  ASSERT_NE(end_status, std::string::npos);
  EXPECT_EQ(sent.substr(end_status, 14), "?Q500\r\n?Q303\r\n");
}

TEST(MdcPoller, CycleEndFallsBackToTheMeasuredTimeWhenTheControlHasNone)
{
  FakeTransport fake;
  scriptedControl(fake, [](const std::string& query, int asked) { return oneCycle(query, asked, ""); });
  const auto events = runOneCycle(fake, true);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[1].type, CycleEventData::kCycleEnd);
  EXPECT_GE(events[1].cycle_time, 0.0);
  EXPECT_LT(events[1].cycle_time, 1.0);  // two 2 ms polls, not a control's value
  EXPECT_EQ(events[1].text.find("from the control"), std::string::npos);
}

TEST(MdcClient, ASevenBitSerialLineIsSetUpAgainAndReopened)
{
  // What the node does after a DNC transfer used the line (applySettings) and after a line outage
  // (a new SerialPort), on a pty as in the tests: a pty keeps 8N1 whatever it is told.
  PtyMaster control;
  SerialSettings settings;
  settings.device = control.slavePath();
  settings.data_bits = 7;
  settings.parity = Parity::kEven;
  {
    SerialPort port(settings);
    EXPECT_NO_THROW(port.applySettings());
    EXPECT_NO_THROW(port.applySettings());
  }
  EXPECT_NO_THROW(SerialPort again(settings));
}

// The watched variables of the `variables` topic: published once every one was polled (a value,
// or NaN with its error), then only on a change; all NaN once when the link is lost.
TEST(MdcVariableWatch, PublishesOnceEveryVariableWasPolledThenOnlyOnChange)
{
  VariableWatch watch({500, 501});
  MachineStatus s;
  s.variables[500] = 0.0;
  EXPECT_FALSE(watch.update(s));  // #501 not polled yet
  s.variable_errors[501] = "no reply within 1000 ms";
  auto values = watch.update(s);
  ASSERT_TRUE(values);
  ASSERT_EQ(values->size(), 2u);
  EXPECT_EQ((*values)[0], 0.0);
  EXPECT_TRUE(std::isnan((*values)[1]));
  EXPECT_EQ(watch.errors(s), "#501: no reply within 1000 ms");
  EXPECT_FALSE(watch.update(s));  // nothing changed, NaN included
  s.variables[500] = 1.0;
  values = watch.update(s);
  ASSERT_TRUE(values);
  EXPECT_EQ((*values)[0], 1.0);
  EXPECT_FALSE(watch.update(s));
  s.variable_errors.erase(501);
  s.variables[501] = 3.0;
  values = watch.update(s);
  ASSERT_TRUE(values);
  EXPECT_EQ((*values)[1], 3.0);
  EXPECT_EQ(watch.errors(s), "");
  values = watch.linkLost();
  ASSERT_TRUE(values);
  EXPECT_TRUE(std::isnan((*values)[0]) && std::isnan((*values)[1]));
  EXPECT_FALSE(watch.linkLost());                 // once
  EXPECT_TRUE(watch.update(s));                   // the values again after the loss, unchanged or not
  EXPECT_FALSE(VariableWatch({500}).linkLost());  // nothing published yet: nothing to take back
}

// A variable without a value is reported with the reason: rejected by the control, no reply, a
// malformed reply; the reason goes once a value arrives, and the poll goes on meanwhile.
TEST(MdcPoller, AVariableWithoutAValueIsReportedWithTheReason)
{
  FakeTransport fake;
  scriptedControl(fake,
                  [](const std::string& query, int asked) -> std::string
                  {
                    if (query == "?Q500")
                      return "PROGRAM, O1, IDLE, PARTS, 1";
                    if (query == "?Q600 500")
                      return "MACRO, 1.5";
                    if (query == "?Q600 9999")
                      return "?, ?Q600 9999";
                    if (query == "?Q600 777")
                      return asked < 1 ? "" : "MACRO, 2";  // the first one unanswered
                    if (query == "?Q600 601")
                      return "MACRO, abc";
                    return "?, " + query;
                  });
  PollPlan plan = fastPlan();
  plan.variables = {500, 9999, 777, 601};
  plan.max_unanswered = 0;
  MdcPoller poller(plan, 30ms);
  Reported reported;
  std::vector<std::string> errors_of_777;
  poller.setListener(
      [&](const MachineStatus& s, const std::vector<CycleEventData>&)
      {
        std::lock_guard<std::mutex> lock(reported.mutex);
        reported.status = s;
        if (s.variable_errors.count(777) &&
            (errors_of_777.empty() || errors_of_777.back() != s.variable_errors.at(777)))
          errors_of_777.push_back(s.variable_errors.at(777));
        reported.changed.notify_all();
      });
  StopSignal stop;
  std::thread thread(
      [&]
      {
        try
        {
          poller.run(fake, stop);
        }
        catch (const Error&)
        {
        }
      });
  EXPECT_TRUE(reported.waitFor(
      [&]
      {
        const auto& s = reported.status;
        return s.variables.count(500) && s.variables.count(777) && s.variable_errors.count(9999) &&
               s.variable_errors.count(601);
      }));
  stop.stop();
  thread.join();
  const auto s = poller.status();
  EXPECT_EQ(s.variables.at(500), 1.5);
  EXPECT_EQ(s.variable_errors.at(9999), "rejected by the control (\"?, ?Q600 9999\")");
  EXPECT_NE(s.variable_errors.at(601).find("malformed reply"), std::string::npos) << s.variable_errors.at(601);
  EXPECT_EQ(s.variables.count(601), 0u);
  EXPECT_EQ(s.variables.at(777), 2.0);
  EXPECT_EQ(s.variable_errors.count(777), 0u);  // gone with the value
  ASSERT_EQ(errors_of_777.size(), 1u);
  EXPECT_EQ(errors_of_777[0], "no reply within 30 ms");
  EXPECT_EQ(s.variable_errors.count(500), 0u);
}

// A Classic control's one RS-232 port carries the program's DPRNT output between MDC replies:
// framed lines are replies, bare lines are the program's, each to its own reader, none lost.
TEST(MdcClient, OnASharedClassicPortBareLinesAreTextAndFramedOnesReplies)
{
  FakeTransport fake;
  // A DPRNT line before the reply (after the previous reply's prompt), one whose first characters
  // look like a reply, a NAK of a control waiting in RECV, the echo of the query, then the reply.
  answerWith(fake, {">X1.0000 Y2.0000\r"
                    "MODE, (MDI)\r"
                    "\x15"
                    "?Q104\r\n"
                    "\x02MODE, (MEM)\x17\r\n>Z-0.5000\r"});
  fake.setMaxReadChunk(5);
  MdcClient client(fake);
  std::vector<std::string> lines;
  client.setTextListener([&](const std::string& line) { lines.push_back(line); });
  const Reply reply = client.request(q(104), 1000ms);
  EXPECT_EQ(valueOf(reply), "(MEM)");
  client.drainForeign(50ms);
  EXPECT_EQ(lines, (std::vector<std::string>{"X1.0000 Y2.0000", "MODE, (MDI)", "Z-0.5000"}));
  EXPECT_EQ(client.stats().text_lines, 3u);
  EXPECT_EQ(client.stats().foreign, 0u);
}

TEST(MdcClient, WithoutATextListenerEveryLineIsParsedAsAReply)
{
  FakeTransport fake;
  answerWith(fake, {"MODE, (MDI)\r\n\x02MODE, (MEM)\x17\r\n"});
  MdcClient client(fake);
  const Reply reply = client.request(q(104), 1000ms);
  EXPECT_EQ(valueOf(reply), "(MDI)");
  EXPECT_EQ(client.stats().text_lines, 0u);
}

// Between polls the poller reads the line, so DPRNT lines come out as they are printed, not at the
// next query, and in the order printed.
TEST(MdcPoller, PassesTheProgramsLinesOnBetweenPolls)
{
  FakeTransport fake;
  PollPlan plan;
  plan.status_period = 10s;  // one poll, then nothing due for the rest of the test
  plan.identity = false;
  plan.counters_period = 10s;
  plan.max_unanswered = 0;  // Q104 gets no answer from this control: no reason to reconnect
  // A Classic: every reply framed, then the prompt.
  fake.onWrite([](FakeTransport& f, const std::vector<uint8_t>&) { f.feed("\x02STATUS, BUSY\x17\r\n>"); });
  MdcPoller poller(plan, 500ms);
  std::mutex m;
  std::condition_variable cv;
  std::vector<std::string> lines;
  poller.setTextListener(
      [&](const std::string& line)
      {
        std::lock_guard<std::mutex> lock(m);
        lines.push_back(line);
        cv.notify_all();
      });
  StopSignal stop;
  std::thread thread([&] { poller.run(fake, stop); });
  ASSERT_TRUE(fake.waitForWritten(1, 5s));
  fake.feed("P1 X1.0\rP2 X2.0\r");
  {
    std::unique_lock<std::mutex> lock(m);
    EXPECT_TRUE(cv.wait_for(lock, 5s, [&] { return lines.size() >= 2; }));
  }
  stop.stop();
  thread.join();
  EXPECT_EQ(lines, (std::vector<std::string>{"P1 X1.0", "P2 X2.0"}));
}

// On a line that also carries DPRNT, the program's lines printed as a transfer ends, before the
// poller has the port again, are the program's output: passed on, not dropped with the transfer's
// leftovers.
TEST(MdcPoller, OnASharedPortTheLinesPrintedAfterATransferAreKept)
{
  const std::string device = "/tmp/cnc_bridge_test_mdc_shared_" + std::to_string(::getpid());
  PortLock mine(device);
  PortLock dnc(device);
  FakeTransport fake;
  fake.onWrite([](FakeTransport& f, const std::vector<uint8_t>&) { f.feed("\x02STATUS, BUSY\x17\r\n>"); });
  PollPlan plan;
  plan.status_period = 5ms;
  plan.identity = false;
  plan.max_unanswered = 0;  // Q104 gets no answer from this control: no reason to reconnect
  MdcPoller poller(plan, 500ms, &mine);
  std::mutex m;
  std::condition_variable cv;
  std::vector<std::string> lines;
  poller.setTextListener(
      [&](const std::string& line)
      {
        std::lock_guard<std::mutex> lock(m);
        lines.push_back(line);
        cv.notify_all();
      });
  StopSignal stop;
  std::thread thread([&] { poller.run(fake, stop); });
  ASSERT_TRUE(fake.waitForWritten(1, 5s));
  ASSERT_TRUE(dnc.lockForTransfer(2s));
  // The control ACKs the transfer's EOT and its program prints on, all before the poller's turn.
  fake.feed("\x06LINE 31\rLINE 32\r");
  dnc.unlock();
  {
    std::unique_lock<std::mutex> lock(m);
    EXPECT_TRUE(cv.wait_for(lock, 5s, [&] { return lines.size() >= 2; }));
  }
  stop.stop();
  thread.join();
  EXPECT_EQ(lines, (std::vector<std::string>{"LINE 31", "LINE 32"}));
  EXPECT_EQ(poller.portRegained(), 1u);
}
