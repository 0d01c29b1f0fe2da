// dnc_node's transfer rules without ROS (include/cnc_bridge/dnc/transfer_rules.h, transfer_gate.h;
// docs/dnc_node.md): the files a request may touch, the refusal while another transfer runs, the
// archive, the XModem waits from the parameters, the feedback throttle, the counters, and one
// transfer at a time with the request listener stepping aside.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <future>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dnc/transfer_gate.h"
#include "cnc_bridge/dnc/transfer_rules.h"
#include "temp_dir.h"
#include "testing/fake_transport.h"

using namespace cnc_bridge;
using namespace cnc_bridge::dnc;
using cnc_bridge::test::TempDir;

namespace
{
struct Files
{
  TempDir dir{"transfer_rules"};
  TempDir archive_dir{"transfer_rules_archive"};
  ProgramDirectory programs{dir.path};
  programs::ProtectedRange protected_range{"O08000-O09999", false, "~allow_protected_programs"};
  programs::NamePattern names{"O%05d.nc"};
  programs::ProgramArchive archive{archive_dir.path + "/kept", 5};
  TransferFiles files{programs, protected_range, names, archive};
};
}  // namespace

TEST(TransferFiles, SendsExistingProgramsInsideTheDirectoryOnly)
{
  Files f;
  f.dir.write("O01234.nc", "%\nO01234\nG0 X0\nM30\n%\n");
  const JobCheck ok = f.files.check("O01234.nc", true);
  EXPECT_TRUE(ok.accepted()) << ok.refusal;
  EXPECT_EQ(ok.path, f.programs.resolveExisting("O01234.nc"));

  const JobCheck missing = f.files.check("O04321.nc", true);
  EXPECT_FALSE(missing.accepted());
  EXPECT_TRUE(missing.path.empty());
  EXPECT_EQ(missing.refusal.rfind("refused: ", 0), 0u) << missing.refusal;
  EXPECT_FALSE(missing.counted);

  const JobCheck outside = f.files.check("../O01234.nc", true);
  EXPECT_FALSE(outside.accepted());
  EXPECT_EQ(outside.refusal.rfind("refused: ", 0), 0u) << outside.refusal;
  EXPECT_FALSE(outside.counted);
}

TEST(TransferFiles, ProtectedProgramsAreRefusedAndCountedOnSendOnly)
{
  Files f;
  f.dir.write("O09010.nc", "%\nO09010 (PROBE)\nM99\n%\n");
  f.dir.write("part.nc", "%\nO08500\nM30\n%\n");  // the number in its first block counts too
  for (const char* name : {"O09010.nc", "part.nc"})
  {
    const JobCheck check = f.files.check(name, true);
    EXPECT_FALSE(check.accepted()) << name;
    EXPECT_TRUE(check.counted) << name;
    EXPECT_NE(check.refusal.find("~allow_protected_programs"), std::string::npos) << check.refusal;
  }
  const JobCheck receive = f.files.check("O09010.nc", false);  // it overwrites nothing on the control
  EXPECT_TRUE(receive.accepted()) << receive.refusal;
  EXPECT_TRUE(f.files.check("new.nc", false).accepted());
}

TEST(TransferFiles, ArchiveKeepsDistinctVersions)
{
  Files f;
  const std::string path = f.dir.write("O01234.nc", "G0 X1\n");
  const programs::VersionSource source{"dnc_node", "vf2", "sent"};
  EXPECT_EQ(f.files.archive(path, source), "kept O01234.nc as version 1 in " + f.archive.root());
  EXPECT_EQ(f.files.archive(path, source), "");  // the same content again
  f.dir.write("O01234.nc", "G0 X2\n");
  EXPECT_EQ(f.files.archive(path, source), "kept O01234.nc as version 2 in " + f.archive.root());
  EXPECT_EQ(f.archive.history("O01234.nc").size(), 2u);
}

TEST(TransferRules, BusyRefusalSaysHowToStopAGoal)
{
  EXPECT_EQ(busyRefusal("/dev/ttyUSB0", "goal g1 (send O1.nc by xmodem)", "/dnc_node/transfer/cancel"),
            "refused: another transfer is running on /dev/ttyUSB0 (one at a time): goal g1 (send O1.nc by "
            "xmodem); to replace it, cancel it first (/dnc_node/transfer/cancel with its goal id)");
  EXPECT_EQ(busyRefusal("/dev/ttyUSB0", "a send_program service call for O1.nc", "/dnc_node/transfer/cancel"),
            "refused: another transfer is running on /dev/ttyUSB0 (one at a time): a send_program service call "
            "for O1.nc; a service call runs to its end: wait for it");
}

TEST(TransferRules, XmodemWaitsFollowTheLineUnlessFixed)
{
  XmodemWaits waits;
  waits.max_retries = 4;
  const xmodem::Config fast = xmodemConfig(waits, 11520.0);  // 115200 baud 8N1
  EXPECT_EQ(fast.char_timeout, Milliseconds(30));            // the floor
  EXPECT_EQ(fast.purge_quiet, Milliseconds(30));
  EXPECT_EQ(fast.stale_nak_settle, Milliseconds(1000));
  EXPECT_EQ(fast.max_retries, 4u);
  EXPECT_EQ(fast.eot_retries, 4u);
  EXPECT_EQ(fast.start_timeout, Milliseconds(120000));

  const xmodem::Config slow = xmodemConfig(waits, 30.0);  // 300 baud: the protocol's one second
  EXPECT_EQ(slow.char_timeout, Milliseconds(1000));

  waits.char_timeout = Milliseconds(200);
  waits.purge_quiet = Milliseconds(300);
  const xmodem::Config fixed = xmodemConfig(waits, 30.0);
  EXPECT_EQ(fixed.char_timeout, Milliseconds(200));
  EXPECT_EQ(fixed.purge_quiet, Milliseconds(300));
  EXPECT_EQ(fixed.stale_nak_settle, Milliseconds(200));
  waits.char_timeout = Milliseconds(5000);
  EXPECT_EQ(xmodemConfig(waits, 30.0).stale_nak_settle, Milliseconds(1000));
}

TEST(TransferRules, ProgressAtMostEveryPeriodAndAlwaysTheLast)
{
  ProgressThrottle throttle(0.1);
  xmodem::Progress p;
  p.total = 1024;
  p.bytes = 128;
  EXPECT_TRUE(throttle.due(1000.0, p));
  EXPECT_FALSE(throttle.due(1000.05, p));
  EXPECT_TRUE(throttle.due(1000.1, p));
  p.bytes = 1024;
  EXPECT_TRUE(throttle.due(1000.11, p));  // the end of the file
  p.total = 0;                            // receiving: no total known
  EXPECT_FALSE(throttle.due(1000.12, p));
}

TEST(TransferRules, CountersByOutcome)
{
  TransferCounters counters;
  counters.started();
  counters.finished(true, false, 10, 1, 1280, "sent O1.nc");
  counters.started();
  counters.finished(false, true, 2, 0, 256, "cancelled");
  EXPECT_FALSE(counters.totals().lastFailed());
  counters.started();
  counters.finished(false, false, 0, 3, 0, "transfer failed: no answer");
  counters.refused();
  counters.xmodemStats(2, 3);
  counters.request(true);
  counters.request(false);
  const TransferTotals totals = counters.totals();
  EXPECT_TRUE(totals.lastFailed());
  EXPECT_EQ(totals.last_result, "transfer failed: no answer");
  const std::vector<std::pair<std::string, uint64_t>> expected{
      {"transfers", 3}, {"completed", 1}, {"failed (aborts)", 1}, {"cancelled", 1}, {"refused", 1},
      {"blocks", 12},   {"retries", 7},   {"timeouts", 2},        {"bytes", 1536}};
  EXPECT_EQ(totals.fields(false), expected);
  const auto with_requests = totals.fields(true);
  ASSERT_EQ(with_requests.size(), expected.size() + 2);
  EXPECT_EQ(with_requests[expected.size()], (std::pair<std::string, uint64_t>{"program requests", 2}));
  EXPECT_EQ(with_requests[expected.size() + 1], (std::pair<std::string, uint64_t>{"program requests served", 1}));
}

TEST(TransferRules, XmodemTransferCountsTheTimeoutsAndRetriesOfAFailure)
{
  TempDir dir("transfer_rules_xmodem");
  const std::string path = dir.write("O00001.nc", "G0 X1\n");
  FakeTransport link;  // a control that asks for the program, then never acknowledges a block
  link.feed(std::string(1, '\x15'));
  XmodemWaits waits;
  waits.ack_timeout = Milliseconds(20);
  waits.max_retries = 2;
  const xmodem::Config config = xmodemConfig(waits, 11520.0);
  TransferCounters counters;
  std::atomic<bool> cancel{false};
  EXPECT_THROW(transferByXmodem(link, path, true, "xmodem", config, {}, nullptr, cancel, counters), Error);
  const TransferTotals totals = counters.totals();
  EXPECT_GE(totals.timeouts, 1u);
  EXPECT_GE(totals.retries, 1u);    // a failed transfer's retries are counted here
  EXPECT_EQ(totals.transfers, 0u);  // started() is the node's

  EXPECT_THROW(transferByXmodem(link, path, true, "zmodem", config, {}, nullptr, cancel, counters), ConfigError);
  EXPECT_EQ(counters.totals().timeouts, totals.timeouts);
}

TEST(TransferGate, OneTransferAtATime)
{
  TransferGate gate;
  gate.cancelFlag() = true;  // a cancel of an earlier transfer
  ASSERT_TRUE(gate.tryReserve("goal g1"));
  EXPECT_FALSE(gate.cancelFlag());  // does not carry over
  EXPECT_FALSE(gate.tryReserve("a send_program service call"));
  std::string running;
  EXPECT_FALSE(gate.tryReserveForPunch("a program request", running));
  EXPECT_EQ(running, "goal g1");
  EXPECT_EQ(gate.running(), "goal g1");
  gate.release();
  EXPECT_TRUE(gate.tryReserveForPunch("a program request", running));
  EXPECT_EQ(gate.running(), "a program request");
  gate.release();
}

TEST(TransferGate, TheListenerLeavesForATransfer)
{
  TransferGate gate;
  ASSERT_TRUE(gate.waitToListen());
  EXPECT_FALSE(gate.listenStop());
  ASSERT_TRUE(gate.tryReserve("goal g1"));
  EXPECT_TRUE(gate.listenStop());  // told to leave
  auto transfer = std::async(std::launch::async, [&gate] { gate.waitForListenerToLeave(); });
  EXPECT_EQ(transfer.wait_for(std::chrono::milliseconds(50)), std::future_status::timeout);  // still there
  gate.leftPort();
  EXPECT_EQ(transfer.wait_for(std::chrono::seconds(5)), std::future_status::ready);

  // The listener waits while the transfer runs, and listens again once it is over.
  auto listener = std::async(std::launch::async, [&gate] { return gate.waitToListen(); });
  EXPECT_EQ(listener.wait_for(std::chrono::milliseconds(50)), std::future_status::timeout);
  gate.release();
  ASSERT_EQ(listener.wait_for(std::chrono::seconds(5)), std::future_status::ready);
  EXPECT_TRUE(listener.get());
  gate.leftPort();
}

TEST(TransferGate, StopEndsTheListener)
{
  TransferGate gate;
  ASSERT_TRUE(gate.tryReserve("goal g1"));
  auto listener = std::async(std::launch::async, [&gate] { return gate.waitToListen(); });
  gate.stopListener();
  ASSERT_EQ(listener.wait_for(std::chrono::seconds(5)), std::future_status::ready);
  EXPECT_FALSE(listener.get());
  EXPECT_TRUE(gate.listenStop());
  const auto start = std::chrono::steady_clock::now();
  gate.pauseListener(std::chrono::seconds(10));  // stopped: no pause
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
}

// ~max_program_bytes / --max-bytes: the cap and the name its errors give; less than a byte refused.
TEST(TransferRules, MaxProgramBytesIsSetWithItsNameAndAtLeastOneByte)
{
  xmodem::Config config;
  dnc::setMaxProgramBytes(config, 4096, "~max_program_bytes");
  EXPECT_EQ(config.max_bytes, 4096u);
  EXPECT_EQ(config.max_bytes_name, "~max_program_bytes");
  try
  {
    dnc::setMaxProgramBytes(config, 0, "~max_program_bytes");
    ADD_FAILURE() << "0 bytes accepted";
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("~max_program_bytes must be at least 1 (bytes), not 0"), std::string::npos);
  }
  EXPECT_EQ(config.max_bytes, 4096u) << "a refused value changed the cap";
}
