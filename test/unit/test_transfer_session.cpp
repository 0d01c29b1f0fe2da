// dnc_node's transfer session without ROS (include/cnc_bridge/dnc/transfer_session.h,
// drip_protocols.h; docs/dnc_node.md): a send and a receive by XModem, a drip-feed and a backup
// against a control played by the test on a pty, what is refused before the port is touched (busy,
// a protected program, a drip-feed while motion is disabled, an unknown protocol), a cancel, a
// port that cannot be opened, and a program request punched by the control and served.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/safety_switch.h"
#include "cnc_bridge/dnc/drip_protocols.h"
#include "cnc_bridge/dnc/transfer_session.h"
#include "cnc_bridge/xmodem/file_transfer.h"
#include "temp_dir.h"
#include "testing/pty.h"

using namespace cnc_bridge;
using namespace cnc_bridge::dnc;
using cnc_bridge::test::readFile;
using cnc_bridge::test::TempDir;

namespace
{
const std::string kProgram = "%\nO01234 (PART)\nG0 X0 Y0\nG1 X10 F100\nM30\n%\n";

/// Records what the session tells the node; waits for an event without sleeping.
class RecordingListener : public TransferListener
{
 public:
  void onLink(LinkState state, const std::string& message) override
  {
    std::lock_guard<std::mutex> lock(mutex_);
    links.emplace_back(state, message);
    changed_.notify_all();
  }
  void onState(const StateChange& change) override
  {
    std::lock_guard<std::mutex> lock(mutex_);
    states.push_back(change);
    changed_.notify_all();
  }
  void onRequest(const RequestEvent& event) override
  {
    std::lock_guard<std::mutex> lock(mutex_);
    requests.push_back(event);
    changed_.notify_all();
  }
  /// Waits until \p done (called under the lock) holds, at most 10 s.
  template <class Predicate>
  bool waitFor(Predicate done)
  {
    std::unique_lock<std::mutex> lock(mutex_);
    return changed_.wait_for(lock, std::chrono::seconds(10), [&] { return done(*this); });
  }
  RequestEvent firstRequest()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return requests.front();
  }

  std::vector<std::pair<LinkState, std::string>> links;
  std::vector<StateChange> states;
  std::vector<RequestEvent> requests;

 private:
  std::mutex mutex_;
  std::condition_variable changed_;
};

xmodem::Config peerConfig()
{
  xmodem::Config c;
  c.nak_interval = Milliseconds(200);
  c.start_timeout = c.start_wait = Milliseconds(5000);
  c.block_timeout = c.ack_timeout = Milliseconds(1000);
  c.char_timeout = Milliseconds(100);
  c.purge_quiet = c.eot_quiet = Milliseconds(20);
  c.stale_nak_settle = Milliseconds(50);
  return c;
}

/// A session on one end of a pty; the test plays the control on the other (pty).
struct SessionFixture : ::testing::Test
{
  TempDir dir{"transfer_session"};
  TempDir archive{"transfer_session_archive"};
  TempDir locks{"transfer_session_locks"};
  PtyMaster pty;
  SafetySwitch motion{{"motion", "/mill/set_motion_enabled", "/mill/enable_motion"}, false};
  RecordingListener listener;
  TransferSettings settings;
  RequestSettings requests;
  DripSettings drip;
  std::unique_ptr<TransferSession> session;

  SessionFixture()
  {
    SerialSettings serial;
    serial.device = pty.slavePath();
    serial.baud = 115200;
    settings.link = LinkSettings::serialLine(serial, InputOnOpen::kKeep);
    settings.lock_dir = locks.path;
    settings.program_dir = dir.path + "/programs";
    settings.archive_dir = archive.path;
    XmodemWaits waits;
    waits.start_timeout = waits.start_wait = Milliseconds(5000);
    waits.nak_interval = Milliseconds(200);
    waits.block_timeout = waits.ack_timeout = Milliseconds(1000);
    settings.xmodem = xmodemConfig(waits, serial.charactersPerSecond());
    drip.drip.flow = DripFlow::kNone;
    drip.backup.start_timeout = Milliseconds(5000);
    drip.backup.quiet_timeout = Milliseconds(300);
  }

  /// Builds the session with the drip and backup protocols, as dnc_node does.
  TransferSession& make()
  {
    SessionParts parts;
    parts.listener = &listener;
    parts.motion = &motion;
    parts.machine = "mill";
    parts.cancel_topic = "/mill/dnc/transfer/cancel";
    session = std::make_unique<TransferSession>(settings, requests, parts);
    auto protocols = std::make_shared<DripProtocols>(drip);
    session->registerProtocol(
        "drip", [protocols](Transport& link, const TransferJob& job, const auto& /*progress*/, const auto& cancel)
        { return protocols->drip(link, job, cancel, nullptr, nullptr); });
    session->registerProtocol(
        "backup", [protocols](Transport& link, const TransferJob& job, const auto& /*progress*/, const auto& cancel)
        { return protocols->backup(link, job, cancel, nullptr); });
    session->start();
    return *session;
  }

  std::string program(const std::string& name) const { return settings.program_dir + "/" + name; }
  void writeProgram(const std::string& name, const std::string& text) const
  {
    std::filesystem::create_directories(settings.program_dir);
    test::writeFile(program(name), text);
  }

  /// What the control received within \p quiet of silence.
  std::string controlReceived(Milliseconds quiet = Milliseconds(300))
  {
    std::string received;
    uint8_t buffer[256];
    while (const size_t n = pty.read(buffer, sizeof(buffer), quiet))
      received.append(reinterpret_cast<const char*>(buffer), n);
    return received;
  }

  /// A refusal: no transfer counted, the port never opened, nothing reached the control.
  void expectNothingSent(TransferSession& s)
  {
    EXPECT_EQ(s.totals().transfers, 0u);
    EXPECT_TRUE(listener.links.empty());
    EXPECT_EQ(controlReceived(), "");
  }

  /// Reads from the control's end until a whole '%'-framed program has arrived (its closing
  /// '%' and the end of block after it), or nothing more comes for 5 s.
  std::string readPercentFramed()
  {
    std::string received;
    uint8_t buffer[256];
    while (std::count(received.begin(), received.end(), '%') < 2 || received.back() != '\n')
    {
      const size_t n = pty.read(buffer, sizeof(buffer), Milliseconds(5000));
      if (n == 0)
        break;
      received.append(reinterpret_cast<const char*>(buffer), n);
    }
    return received;
  }

  static TransferRequest request(const std::string& direction, const std::string& file,
                                 const std::string& protocol = "")
  {
    TransferRequest r;
    r.direction = direction;
    r.file = file;
    r.protocol = protocol;
    return r;
  }
};

size_t archivedVersions(const std::string& root)
{
  if (!std::filesystem::exists(root))
    return 0;
  size_t files = 0;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(root))
    files += entry.is_regular_file() && entry.path().filename().string().find(".nc") != std::string::npos ? 1 : 0;
  return files;
}
}  // namespace

TEST_F(SessionFixture, SendsByXmodemCountsArchivesAndClosesThePortAfter)
{
  writeProgram("O01234.nc", kProgram);
  TransferSession& s = make();
  auto control = std::async(std::launch::async,
                            [&]
                            {
                              xmodem::receiveFile(pty, dir.path + "/at_control.nc", xmodem::Mode::kChecksum,
                                                  peerConfig(), xmodem::TextOptions());
                              return readFile(dir.path + "/at_control.nc");
                            });
  std::vector<TransferProgress> progress;
  const TransferOutcome outcome =
      s.run(request(kDirectionSend, "O01234.nc"), [&](const TransferProgress& p) { progress.push_back(p); });
  ASSERT_TRUE(outcome.success) << outcome.message;
  EXPECT_EQ(control.get(), kProgram);
  EXPECT_EQ(outcome.bytes, kProgram.size());
  EXPECT_GE(outcome.blocks, 1u);
  ASSERT_FALSE(progress.empty());
  EXPECT_EQ(progress.back().bytes, kProgram.size());

  const TransferTotals totals = s.totals();
  EXPECT_EQ(totals.transfers, 1u);
  EXPECT_EQ(totals.completed, 1u);
  EXPECT_EQ(totals.bytes, kProgram.size());
  EXPECT_EQ(archivedVersions(archive.path), 1u);
  // Shown while it ran and after; the port opened for it and closed again (not kept open).
  ASSERT_FALSE(listener.states.empty());
  EXPECT_EQ(listener.states.front().execution, Execution::kActive);
  EXPECT_EQ(listener.states.front().program, std::string("O01234.nc"));
  EXPECT_EQ(listener.states.back().execution, Execution::kReady);
  ASSERT_GE(listener.links.size(), 3u);
  EXPECT_EQ(listener.links[0].first, LinkState::kConnecting);
  EXPECT_EQ(listener.links[1].first, LinkState::kUp);
  EXPECT_EQ(listener.links.back().first, LinkState::kDown);
}

TEST_F(SessionFixture, ReceivesByXmodemIntoTheProgramDirectory)
{
  TransferSession& s = make();
  test::writeFile(dir.path + "/punched.nc", kProgram);
  auto control = std::async(std::launch::async,
                            [&] {
                              xmodem::sendFile(pty, dir.path + "/punched.nc", xmodem::Mode::kChecksum, peerConfig(),
                                               xmodem::TextOptions());
                            });
  const TransferOutcome outcome = s.run(request(kDirectionReceive, "O04321.nc", "xmodem"), nullptr);
  control.get();
  ASSERT_TRUE(outcome.success) << outcome.message;
  EXPECT_EQ(readFile(program("O04321.nc")), kProgram);
  EXPECT_EQ(s.totals().completed, 1u);
  EXPECT_EQ(archivedVersions(archive.path), 1u);
}

TEST_F(SessionFixture, ASecondTransferIsRefusedWithWhatRunsAndNothingReachesTheControl)
{
  writeProgram("O01234.nc", kProgram);
  TransferSession& s = make();
  ASSERT_TRUE(s.tryReserve("goal 7 (send O05555.nc by xmodem)"));
  const TransferOutcome outcome = s.run(request(kDirectionSend, "O01234.nc"), nullptr);
  EXPECT_FALSE(outcome.success);
  EXPECT_NE(outcome.message.find("refused: another transfer is running on " + pty.slavePath()), std::string::npos)
      << outcome.message;
  EXPECT_NE(outcome.message.find("goal 7"), std::string::npos) << outcome.message;
  EXPECT_NE(outcome.message.find("/mill/dnc/transfer/cancel"), std::string::npos) << outcome.message;
  EXPECT_FALSE(s.tryReserve("another goal"));
  EXPECT_EQ(s.totals().refused, 2u);
  EXPECT_EQ(s.totals().transfers, 0u);
  s.release();
  EXPECT_TRUE(listener.links.empty());  // the port was never opened
  EXPECT_EQ(controlReceived(), "");
}

TEST_F(SessionFixture, AProtectedProgramIsRefusedBeforeThePortIsOpened)
{
  writeProgram("O09010.nc", "%\nO09010 (PROBE)\nM99\n%\n");
  TransferSession& s = make();
  const TransferOutcome outcome = s.run(request(kDirectionSend, "O09010.nc"), nullptr);
  EXPECT_FALSE(outcome.success);
  EXPECT_EQ(outcome.message.rfind("refused: ", 0), 0u) << outcome.message;
  EXPECT_NE(outcome.message.find("~allow_protected_programs"), std::string::npos) << outcome.message;
  EXPECT_EQ(s.totals().refused, 1u);
  expectNothingSent(s);
}

TEST_F(SessionFixture, UnknownProtocolsDirectionsAndFilesOutsideAreRefused)
{
  writeProgram("O01234.nc", kProgram);
  TransferSession& s = make();
  const TransferOutcome protocol = s.run(request(kDirectionSend, "O01234.nc", "zmodem"), nullptr);
  EXPECT_EQ(protocol.message.rfind("refused: unknown protocol 'zmodem' (known: backup, drip, xmodem", 0), 0u)
      << protocol.message;
  const TransferOutcome direction = s.run(request("upload", "O01234.nc"), nullptr);
  EXPECT_EQ(direction.message, "refused: direction must be 'send' or 'receive', not 'upload'");
  const TransferOutcome outside = s.run(request(kDirectionSend, "../O01234.nc"), nullptr);
  EXPECT_EQ(outside.message.rfind("refused: ", 0), 0u) << outside.message;
  expectNothingSent(s);
}

TEST_F(SessionFixture, ADripFeedIsRefusedWhileMotionIsDisabledAndSendsNothing)
{
  writeProgram("O01234.nc", kProgram);
  TransferSession& s = make();
  const TransferOutcome outcome = s.run(request(kDirectionSend, "O01234.nc", "drip"), nullptr);
  EXPECT_FALSE(outcome.success);
  EXPECT_EQ(
      outcome.message.rfind("refused: a drip-feed (the control runs it as it arrives) refused: motion is disabled", 0),
      0u)
      << outcome.message;
  EXPECT_NE(outcome.message.find("/mill/set_motion_enabled"), std::string::npos) << outcome.message;
  expectNothingSent(s);
}

TEST_F(SessionFixture, ADripFeedSendsTheProgramWhenMotionIsEnabled)
{
  writeProgram("O01234.nc", kProgram);
  motion.set(true, "test");
  TransferSession& s = make();
  auto control = std::async(std::launch::async, [&] { return readPercentFramed(); });
  const TransferOutcome outcome = s.run(request(kDirectionSend, "O01234.nc", "drip"), nullptr);
  ASSERT_TRUE(outcome.success) << outcome.message;
  EXPECT_EQ(control.get(), kProgram);
  EXPECT_GE(outcome.stopped_at_line, 5u);  // through M30
  EXPECT_EQ(s.totals().completed, 1u);
  EXPECT_EQ(archivedVersions(archive.path), 1u);
}

TEST_F(SessionFixture, ABackupStoresWhatTheControlPunches)
{
  TransferSession& s = make();
  auto control = std::async(std::launch::async,
                            [&]
                            {
                              // The control punches once the host says it is ready (DC1).
                              uint8_t byte = 0;
                              while (pty.read(&byte, 1, Milliseconds(5000)) == 1 && byte != 0x11)
                              {
                              }
                              pty.write(std::string("\x12%\nO04321\nG0 X1\nM30\n%\n\x14"));
                            });
  const TransferOutcome outcome = s.run(request(kDirectionReceive, "O04321.nc", "backup"), nullptr);
  control.get();
  ASSERT_TRUE(outcome.success) << outcome.message;
  EXPECT_EQ(readFile(program("O04321.nc")), "%\nO04321\nG0 X1\nM30\n%\n");
  EXPECT_EQ(s.totals().completed, 1u);
}

TEST_F(SessionFixture, ACancelStopsATransferWaitingForTheControl)
{
  writeProgram("O01234.nc", kProgram);
  TransferSession& s = make();
  ASSERT_TRUE(s.tryReserve("goal 1 (send O01234.nc by xmodem)"));
  auto running =
      std::async(std::launch::async, [&] { return s.runReserved(request(kDirectionSend, "O01234.nc"), nullptr); });
  // The sender waits for the control's NAK, which never comes, once the port is open.
  ASSERT_TRUE(listener.waitFor([](RecordingListener& l)
                               { return !l.links.empty() && l.links.back().first == LinkState::kUp; }));
  s.cancelRunning();
  const TransferOutcome outcome = running.get();
  s.release();
  EXPECT_FALSE(outcome.success);
  EXPECT_TRUE(outcome.cancelled) << outcome.message;
  EXPECT_EQ(s.totals().cancelled, 1u);
  EXPECT_EQ(listener.states.back().execution, Execution::kStopped);
}

TEST_F(SessionFixture, APortThatCannotBeOpenedFailsTheTransferAndShowsTheLinkDown)
{
  writeProgram("O01234.nc", kProgram);
  settings.link.serial.device = dir.path + "/no_such_tty";
  TransferSession& s = make();
  const TransferOutcome outcome = s.run(request(kDirectionSend, "O01234.nc"), nullptr);
  EXPECT_FALSE(outcome.success);
  EXPECT_NE(outcome.message.find("no_such_tty"), std::string::npos) << outcome.message;
  EXPECT_EQ(s.totals().failed, 1u);
  ASSERT_FALSE(listener.links.empty());
  EXPECT_EQ(listener.links.back().first, LinkState::kDown);
  EXPECT_EQ(listener.states.back().execution, Execution::kStopped);
}

TEST_F(SessionFixture, APunchedLoadRequestIsAnsweredByADripFeed)
{
  writeProgram("O01234.nc", kProgram);
  motion.set(true, "test");
  requests.enabled = true;
  requests.mode = "drip";
  requests.listener.wire = RequestWire::kText;
  requests.listener.text_quiet = Milliseconds(300);
  TransferSession& s = make();
  ASSERT_TRUE(listener.waitFor([](RecordingListener& l) { return !l.links.empty(); }));
  pty.write(std::string("%\nO00001 (LOAD O1234)\nM30\n%\n"));
  EXPECT_EQ(readPercentFramed(), kProgram);
  ASSERT_TRUE(listener.waitFor([](RecordingListener& l) { return !l.requests.empty(); }));
  const RequestEvent event = listener.firstRequest();
  EXPECT_TRUE(event.success) << event.outcome;
  EXPECT_EQ(event.request, "LOAD");
  EXPECT_EQ(event.number, 1234u);
  EXPECT_EQ(event.program, "O01234.nc");
  EXPECT_EQ(s.totals().requests, 1u);
  EXPECT_EQ(s.totals().requests_served, 1u);
  EXPECT_EQ(s.totals().completed, 1u);
}

TEST_F(SessionFixture, APunchedRequestForAProtectedProgramIsAnsweredWithARefusal)
{
  writeProgram("O09010.nc", "%\nO09010 (PROBE)\nM99\n%\n");
  requests.enabled = true;
  requests.mode = "drip";
  requests.listener.wire = RequestWire::kText;
  requests.listener.text_quiet = Milliseconds(300);
  TransferSession& s = make();
  ASSERT_TRUE(listener.waitFor([](RecordingListener& l) { return !l.links.empty(); }));
  pty.write(std::string("%\nO00001 (LOAD O9010)\nM30\n%\n"));
  const std::string answer = readPercentFramed();
  // The answer replaces the request program (O00001), never the protected one.
  EXPECT_NE(answer.find("O00001"), std::string::npos) << answer;
  EXPECT_EQ(answer.find("M99"), std::string::npos) << answer;
  ASSERT_TRUE(listener.waitFor([](RecordingListener& l) { return !l.requests.empty(); }));
  EXPECT_FALSE(listener.firstRequest().success);
  EXPECT_EQ(s.totals().requests_served, 0u);
  EXPECT_EQ(s.totals().transfers, 0u);
}
