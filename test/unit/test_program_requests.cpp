// Program requests over RS-232 (include/cnc_bridge/dnc/program_requests.h) and what is done about
// a request (programs::decideRequest). The control is played by independent programs where one
// exists: lrzsz `sx` punches the request by XModem, as a Haas set to XMODEM does (it waits for the
// PC's NAK, then sends checksum blocks: OpenDNC's Haas capture, test/data/xmodem/haas_xmodem_capture.json),
// and the python3-xmodem package (test/data/xmodem/pyxmodem_peer.py) receives the answer. The text
// punch of a control set to XON/XOFF is written by the test on a pty; the bytes of a real Haas punch
// come from OpenDNC's Haas capture (test/data/xmodem/haas_xmodem_capture.json).
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dnc/program_requests.h"
#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/programs/program_request.h"
#include "cnc_bridge/transport/serial_port.h"
#include "cnc_bridge/xmodem/packet.h"
#include "haas_capture.h"
#include "peer_process.h"
#include "temp_dir.h"
#include "testing/fake_transport.h"
#include "testing/pty.h"

using namespace cnc_bridge;
using namespace cnc_bridge::programs;
using cnc_bridge::dnc::RequestListener;
using cnc_bridge::dnc::RequestListenerOptions;
using cnc_bridge::dnc::RequestWire;
using cnc_bridge::test::Peer;
using cnc_bridge::test::readFile;
using cnc_bridge::test::TempDir;

namespace
{
const std::string kPython = std::string(XMODEM_TEST_DATA) + "/pyxmodem_peer.py";
const std::atomic<bool> kNever{false};
const auto kAlways = [] { return true; };

RequestListenerOptions xmodemOptions()
{
  RequestListenerOptions options;
  options.wire = RequestWire::kXmodem;
  // lrzsz sx flushes its input as it starts, so a NAK written before that is lost: ask again soon.
  options.xmodem.nak_interval = Milliseconds(500);
  options.xmodem.start_wait = Milliseconds(20000);
  options.xmodem.block_timeout = Milliseconds(5000);
  return options;
}

std::string stripPadding(std::string text)
{
  while (!text.empty() && text.back() == static_cast<char>(xmodem::kSub))
    text.pop_back();
  return text;
}
}  // namespace

TEST(RequestDecision, LoadSendsAnExistingProgramAndExplainsEveryRefusal)
{
  TempDir dir("test_program_requests");
  dir.write("O01234.nc", "%\nO01234 (PART)\nM30\n%\n");
  dir.write("O09000.nc", "%\nO09000 (PROBE)\nM99\n%\n");
  const NamePattern pattern("O%05d.nc");
  const ProtectedRange guarded("O08000-O09999", false, "~allow_protected_programs");
  const ProtectedRange allowed("O08000-O09999", true, "~allow_protected_programs");
  auto decide = [&](const std::string& punch, const ProtectedRange& range)
  { return decideRequest(*recogniseRequest(punch), pattern, range, dir.path); };

  RequestDecision d = decide("(LOAD O1234)", guarded);
  EXPECT_EQ(d.action, RequestDecision::Action::kSend);
  EXPECT_EQ(d.program, "O01234.nc");

  d = decide("(SEND O4444)", guarded);
  EXPECT_EQ(d.action, RequestDecision::Action::kRefuse);
  EXPECT_EQ(d.outcome, "no O04444.nc in " + dir.path);
  EXPECT_EQ(d.shown, "O04444 NOT FOUND IN PROGRAMS");

  d = decide("(LOAD O9000)", guarded);
  EXPECT_EQ(d.action, RequestDecision::Action::kRefuse);
  EXPECT_NE(d.outcome.find("~allow_protected_programs"), std::string::npos) << d.outcome;
  EXPECT_NE(d.outcome.find("O08000-O09999"), std::string::npos) << d.outcome;
  EXPECT_EQ(d.shown, "O09000 PROTECTED - NOT SENT");
  EXPECT_EQ(decide("(LOAD O9000)", allowed).action, RequestDecision::Action::kSend);

  // Receiving a protected number overwrites nothing on the control.
  d = decide("(SAVE O9001)", guarded);
  EXPECT_EQ(d.action, RequestDecision::Action::kReceive);
  EXPECT_EQ(d.program, "O09001.nc");
}

TEST(RequestDecision, TheAnswerProgramIsShortUppercaseAndLoadable)
{
  const std::string answer = answerProgram(1, "O04444 not found (ask the office) and a much longer tail");
  EXPECT_EQ(answer, "%\nO00001 (O04444 NOT FOUND  ASK THE OFFICE)\nM30\n%\n");
  const ProgramHeader header = readHeader(answer);
  EXPECT_EQ(header.number, 1u);
  EXPECT_LE(header.comment.size(), kAnswerCommentLength);
}

// The Haas case of OpenDNC's Haas capture: the control is an XModem sender that waits for the PC's NAK.
TEST(RequestListener, XmodemPunchBySxIsReadAndTheAnswerReachesPythonXmodem)
{
  TempDir dir("test_program_requests");
  const std::string request = "%\nO00001 (LOAD O4444)\nM30\n%\n";
  dir.write("request.nc", request);
  PtyMaster pty;
  RequestListener listener(pty, xmodemOptions());
  Peer sx({"/usr/bin/sx", "request.nc"}, dir.path, pty.slavePath());
  const auto punch = listener.listen(kNever, kAlways);
  ASSERT_TRUE(punch);
  EXPECT_EQ(sx.wait(), 0) << "sx did not complete its send";
  EXPECT_EQ(punch->text, request);
  EXPECT_EQ(punch->how, "by XModem, 1 blocks");
  const auto parsed = recogniseRequest(punch->text);
  ASSERT_TRUE(parsed);
  EXPECT_EQ(parsed->number, 4444u);

  // The operator switches the control to receive: python3-xmodem as the receiving control.
  const std::string answer = answerProgram(readHeader(punch->text).number.value_or(1), "O04444 NOT FOUND IN PROGRAMS");
  Peer control({"/usr/bin/python3", kPython, "recv", "checksum", pty.slavePath(), dir.file("answer.nc")}, dir.path, "");
  EXPECT_EQ(listener.answer(answer), "answered by XModem (1 blocks)");
  ASSERT_EQ(control.wait(), 0) << "python3-xmodem did not receive the answer";
  EXPECT_EQ(stripPadding(readFile(dir.file("answer.nc"))), "%\nO00001 (O04444 NOT FOUND IN PROGRAMS)\nM30\n%\n");
}

// Idle, the listener writes nothing but its NAKs and leaves the line when asked to.
TEST(RequestListener, IdleListenerStopsOnRequestHavingWrittenOnlyNaks)
{
  PtyMaster control;
  SerialSettings settings;
  settings.device = control.slavePath();
  settings.baud = 115200;
  SerialPort pc(settings);
  RequestListener listener(pc, xmodemOptions());
  std::atomic<bool> stop{false};
  std::string seen;
  std::thread watcher(
      [&]
      {
        // Two invitations seen, then the node needs the line for a transfer.
        while (seen.size() < 2)
        {
          uint8_t byte = 0;
          if (control.read(&byte, 1, Milliseconds(5000)) == 0)
            break;
          seen.push_back(static_cast<char>(byte));
        }
        stop = true;
      });
  bool asked = false;
  const auto punch = listener.listen(stop, [&] { return asked = true; });
  watcher.join();
  EXPECT_FALSE(punch);
  EXPECT_FALSE(asked);
  EXPECT_EQ(seen, "\x15\x15");
  uint8_t extra = 0;
  EXPECT_EQ(control.read(&extra, 1, Milliseconds(100)), 0u) << "wrote after it was stopped";
}

// A control set to XON/XOFF punches text unasked; the SAVE's program may follow at once.
TEST(RequestListener, TextPunchesAreReadOneAfterTheOther)
{
  PtyMaster control;
  RequestListenerOptions options;
  options.wire = RequestWire::kText;
  RequestListener listener(control, options);
  const std::string stream = std::string("\0\0\0", 3) + "%\r\nO00002 (SAVE O1234)\r\nM30\r\n%\r\n" +
                             "%\r\nO01234 (NEW PART)\r\nG00 X1.\r\nM30\r\n%\r\n";
  std::thread punch_thread(
      [&]
      {
        SerialSettings settings;
        settings.device = control.slavePath();
        SerialPort cnc(settings);
        cnc.write(stream);
        cnc.drain();
      });
  const auto request = listener.listen(kNever, kAlways);
  punch_thread.join();
  ASSERT_TRUE(request);
  EXPECT_EQ(request->text, "%\nO00002 (SAVE O1234)\nM30\n%\n");
  const auto program = listener.listen(kNever, kAlways, Milliseconds(2000));
  ASSERT_TRUE(program);
  EXPECT_EQ(program->text, "%\nO01234 (NEW PART)\nG00 X1.\nM30\n%\n");
  // Nothing more follows: a SAVE whose program never comes ends with the reason.
  EXPECT_THROW(listener.listen(kNever, kAlways, Milliseconds(200)), TimeoutError);
}

// A punch that begins while the node needs the line is left unread.
TEST(RequestListener, APunchRefusedByTheNodeIsNotRead)
{
  PtyMaster control;
  RequestListenerOptions options;
  options.wire = RequestWire::kText;
  RequestListener listener(control, options);
  std::thread punch_thread(
      [&]
      {
        SerialSettings settings;
        settings.device = control.slavePath();
        SerialPort cnc(settings);
        cnc.write(std::string("%\nO00002 (LOAD O1)\n%\n"));
        cnc.drain();
      });
  bool asked = false;
  EXPECT_FALSE(listener.listen(kNever,
                               [&]
                               {
                                 asked = true;
                                 return false;
                               }));
  punch_thread.join();
  EXPECT_TRUE(asked);
}

// The Haas of OpenDNC's Haas capture, as sim_haas_serial xmodem plays it: it NAKs while it waits to receive,
// punches its program on the PC's NAK once its operator pressed SEND (--send), and answers the
// EOT of a program it received with CAN CAN CAN. The answer must be taken as delivered.
TEST(RequestListener, TheSimulatedHaasPunchesARequestAndStoresTheAnswer)
{
  TempDir dir("test_program_requests");
  const std::string link = dir.file("haas");
  const std::string memory = dir.file("memory");
  std::filesystem::create_directory(memory);
  dir.write("request.nc", "%\nO00031 (LOAD O1234)\nM30\n%\n");
  Peer haas({SIM_HAAS_SERIAL, "xmodem", "--link", link, "--dir", memory, "--program", dir.file("request.nc"),
             "--send-on", "signal", "--send", "--nak-interval", "0.2", "--timeout-scale", "0.2"},
            dir.path, "");
  for (int i = 0; i < 1000 && !test::exists(link); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));  // poll: the simulator makes its pty as it starts
  SerialSettings settings;
  settings.device = link;
  SerialPort pc(settings);
  RequestListener listener(pc, xmodemOptions());
  const auto punch = listener.listen(kNever, kAlways);
  ASSERT_TRUE(punch);
  const auto request = recogniseRequest(punch->text);
  ASSERT_TRUE(request);
  EXPECT_EQ(request->number, 1234u);
  const std::string answer = answerProgram(31, "O01234 NOT FOUND IN PROGRAMS");
  EXPECT_EQ(listener.answer(answer), "answered by XModem (1 blocks)");  // CAN CAN CAN after EOT: delivered
  // The control stores a received program under its O number, atomically.
  const std::string stored = memory + "/O00031.nc";
  for (int i = 0; i < 500 && !test::exists(stored); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));  // poll: its rename has no event to wait on here
  EXPECT_EQ(readFile(stored), answer);
}

// The bytes a real Haas punched (OpenDNC's Haas capture, exchange cnc_to_pc: the control sends O05555
// after the PC's NAK, checksum blocks beginning with LF %, EOT) are read whole by the listener, and
// the PC side writes what the PC of that capture wrote: NAK, an ACK per block and one for EOT.
TEST(RequestListener, AHaasPunchFromTheCaptureIsReadWhole)
{
  std::vector<test::Bytes> control;
  test::Bytes pc_wrote_in_capture;
  for (const auto& event : test::capture("cnc_to_pc"))
  {
    if (event.from_pc)
      pc_wrote_in_capture.insert(pc_wrote_in_capture.end(), event.bytes.begin(), event.bytes.end());
    else
      control.push_back(event.bytes);
  }
  FakeTransport cnc("haas");
  auto next = std::make_shared<size_t>(0);
  cnc.onWrite(
      [&control, next](FakeTransport& t, const test::Bytes&)
      {
        if (*next < control.size())
          t.feed(control[(*next)++]);  // each NAK or ACK of the PC answered by the next transmission
      });
  RequestListenerOptions options = xmodemOptions();
  options.xmodem.eot_quiet = Milliseconds(20);
  RequestListener listener(cnc, options);
  const auto punch = listener.listen(kNever, kAlways);
  ASSERT_TRUE(punch);
  EXPECT_EQ(punch->text, readFile(std::string(XMODEM_TEST_DATA) + "/haas_O05555.nc"));
  EXPECT_EQ(punch->how, "by XModem, 8 blocks");
  // The PC of OpenDNC's Haas capture sent two NAKs before block 1 came; this one needed one.
  test::Bytes expected = pc_wrote_in_capture;
  expected.erase(expected.begin());
  EXPECT_EQ(cnc.written(), expected);
  EXPECT_FALSE(recogniseRequest(punch->text)) << "O05555 is a program, not a request";
}

TEST(RequestListener, RequestModeNames)
{
  EXPECT_EQ(dnc::parseRequestWire("xmodem"), RequestWire::kXmodem);
  EXPECT_EQ(dnc::parseRequestWire("drip"), RequestWire::kText);
  EXPECT_THROW(dnc::parseRequestWire("zmodem"), ConfigError);
}
