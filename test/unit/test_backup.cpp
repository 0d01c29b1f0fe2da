// Unit tests of program backup: the parser's byte rules (leader, parity, DC codes, EOB runs, the
// closing '%'), the receiver's timeouts, cancel and atomic file, and end to end on a pty against
// the simulated control punching a program (CR LF, leader, DC2/DC4, 7E1, with and without the
// closing '%'). Programs are written by the tests.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <future>
#include <sstream>
#include <string>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dnc/backup.h"
#include "cnc_bridge/dnc/dnc_codes.h"
#include "cnc_bridge/transport/serial_port.h"
#include "dnc_sim.h"
#include "temp_dir.h"
#include "testing/fake_transport.h"
#include "testing/paced_transport.h"
#include "testing/pty.h"

using namespace cnc_bridge;
using namespace cnc_bridge::dnc;
using namespace cnc_bridge::test;

namespace
{
const std::string kProgram =
    "%\n"
    "O0042 (BACKUP TEST)\n"
    "N10 G20 G90 G54\n"
    "N20 T2 M6\n"
    "N30 S1500 M3\n"
    "N40 G0 X1. Y1.\n"
    "N50 G1 Z-.1 F20.\n"
    "N60 M30\n"
    "%\n";
}  // namespace

TEST(BackupParser, DropsLeaderAndControlCodesAndCollapsesEob)
{
  BackupParser parser;
  std::string out;
  const std::string punched =
      std::string(5, '\0') + "\x7f\n\x12%\r\nG0 X1\r\n\r\nG1\tY2\n\r\r\x14" + "%\r\n" + std::string(3, '\0');
  const size_t used = parser.feed(reinterpret_cast<const uint8_t*>(punched.data()), punched.size(), out);
  EXPECT_EQ("%\nG0 X1\nG1\tY2\n%\n", out);
  EXPECT_EQ(BackupParser::State::kDone, parser.state());
  EXPECT_EQ(punched.size() - 5, used);  // the CR LF and trailer after the closing '%' are not consumed
  EXPECT_EQ(4u, parser.lines());
  EXPECT_EQ(8u, parser.leaderBytes());
}

TEST(BackupParser, MasksTheParityBitAndTakesBytesOneAtATime)
{
  const std::string plain = "%\r\nN1 G0\r\n%\r\n";
  BackupParser parser;
  std::string out;
  for (const char c : plain)
  {
    const uint8_t with_parity = withEvenParity(static_cast<uint8_t>(c));
    parser.feed(&with_parity, 1, out);
  }
  EXPECT_EQ("%\nN1 G0\n%\n", out);
}

TEST(BackupParser, FinishClosesTheLastLineWithoutAClosingPercent)
{
  BackupParser parser;
  std::string out;
  const std::string punched = "%\nG0 X1\nM30";
  parser.feed(reinterpret_cast<const uint8_t*>(punched.data()), punched.size(), out);
  EXPECT_EQ(BackupParser::State::kInProgram, parser.state());
  parser.finish(out);
  EXPECT_EQ("%\nG0 X1\nM30\n", out);
}

TEST(BackupReceiver, NoProgramWithinTheStartTimeoutLeavesNoFile)
{
  TempDir dir("test_backup");
  FakeTransport link;
  link.feed(std::string(10, '\0'));  // leader only
  BackupOptions options;
  options.start_timeout = Milliseconds(100);
  BackupReceiver receiver(link, options);
  EXPECT_THROW(receiver.receive(dir.file("out.nc")), TimeoutError);
  EXPECT_FALSE(exists(dir.file("out.nc")));
  EXPECT_EQ(std::vector<uint8_t>{kDc1}, link.written());  // it told the control it was ready
}

TEST(BackupReceiver, CancelKeepsTheOldFileIntact)
{
  TempDir dir("test_backup");
  const auto target = dir.write("out.nc", "old\n");
  FakeTransport link;
  BackupReceiver receiver(link, BackupOptions{});
  std::promise<void> started;
  bool signalled = false;
  auto done = std::async(std::launch::async,
                         [&]
                         {
                           return receiver.receive(target,
                                                   [&](const BackupProgress& p)
                                                   {
                                                     if (p.started && !signalled)
                                                     {
                                                       signalled = true;
                                                       started.set_value();
                                                     }
                                                   });
                         });
  link.feed("%\nG0 X1\n");
  ASSERT_EQ(std::future_status::ready, started.get_future().wait_for(std::chrono::seconds(5)));
  receiver.cancel();
  EXPECT_THROW(done.get(), CancelledError);
  EXPECT_EQ("old\n", readFile(target));
}

TEST(BackupReceiver, ABabblingLineIsRefused)
{
  TempDir dir("test_backup");
  FakeTransport link;
  link.feed("%\n" + std::string(5000, 'X'));
  BackupOptions options;
  options.max_bytes = 1000;
  BackupReceiver receiver(link, options);
  EXPECT_THROW(receiver.receive(dir.file("out.nc")), ProtocolError);
  EXPECT_FALSE(exists(dir.file("out.nc")));
}

// ---------------------------------------------------------------------------------------------
// End to end: the simulated control punches, the receiver stores.

namespace
{
BackupResult punchAndReceive(const std::string& program_path, const sim::PunchOptions& punch,
                             const SerialSettings& port_settings, const BackupOptions& options,
                             const std::string& target, double line_cps)
{
  PtyMaster pty;
  PacedTransport paced(pty, line_cps);
  StopSignal stop;
  auto punched = std::async(std::launch::async, [&] { return sim::punchProgram(paced, program_path, punch, stop); });
  SerialSettings settings = port_settings;
  settings.device = pty.slavePath();
  SerialPort port(settings);
  BackupReceiver receiver(port, options);
  const auto result = receiver.receive(target);
  EXPECT_GT(punched.get(), 0u);
  return result;
}
}  // namespace

TEST(BackupEndToEnd, StoredProgramEqualsThePunchedOneCrLfLeaderDcCodes)
{
  TempDir dir("test_backup");
  const auto program = dir.write("program.nc", kProgram);
  sim::PunchOptions punch;  // CR LF, 16 NULs, DC2/DC4, closing '%', waits for our DC1
  const auto result = punchAndReceive(program, punch, SerialSettings{}, BackupOptions{}, dir.file("backup.nc"), 11520);
  EXPECT_TRUE(result.ended_by_percent);
  EXPECT_EQ(kProgram, readFile(dir.file("backup.nc")));
  EXPECT_EQ(kProgram.size(), result.bytes);
  EXPECT_EQ(9u, result.lines);
}

TEST(BackupEndToEnd, SevenE1Punch)
{
  TempDir dir("test_backup");
  const auto program = dir.write("program.nc", kProgram);
  sim::PunchOptions punch;
  punch.seven_e1 = true;
  punch.eob = "\n";
  SerialSettings settings;
  settings.data_bits = 7;
  settings.parity = Parity::kEven;
  const auto result = punchAndReceive(program, punch, settings, BackupOptions{}, dir.file("backup.nc"), 960);
  EXPECT_TRUE(result.ended_by_percent);
  EXPECT_EQ(kProgram, readFile(dir.file("backup.nc")));
}

TEST(BackupEndToEnd, WithoutTheClosingPercentTheQuietTimeoutEndsIt)
{
  TempDir dir("test_backup");
  // The file lacks '%' framing entirely; the control adds the opening one and, set so, no closing.
  const std::string body = "O0043\nG0 X1\nM30\n";
  const auto program = dir.write("program.nc", body);
  sim::PunchOptions punch;
  punch.end_percent = false;
  BackupOptions options;
  options.quiet_timeout = Milliseconds(300);
  const auto result = punchAndReceive(program, punch, SerialSettings{}, options, dir.file("backup.nc"), 11520);
  EXPECT_FALSE(result.ended_by_percent);
  EXPECT_NE(result.message.find("quiet"), std::string::npos);
  EXPECT_EQ("%\n" + body, readFile(dir.file("backup.nc")));
}
