// dnc_node's program requests (test/rostest/dnc_requests.test): the node on one end of a socat pty
// pair, the control on the other, played by independent XModem programs as a Haas set to XMODEM
// behaves: python3-xmodem (test/data/xmodem/pyxmodem_peer.py) and lrzsz sx punch, as the sender
// that waits for the PC's NAK; python3-xmodem receives what the node answers. Every wait is on a
// peer's exit, a message or a service reply, with a deadline; nothing sleeps.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <ros/ros.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <future>
#include <string>
#include <vector>

#include "../unit/peer_process.h"
#include "../unit/temp_dir.h"
#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/ProgramRequestEvent.h"
#include "cnc_bridge/ReceiveProgram.h"
#include "cnc_bridge/programs/archive.h"
#include "line_log.h"
#include "topic_watch.h"

using cnc_bridge::ProgramRequestEvent;
using cnc_bridge::test::Peer;
using cnc_bridge::test::readFile;
using cnc_bridge::test::TempDir;

namespace
{
std::string param(const std::string& name)
{
  std::string value;
  ros::NodeHandle("~").getParam(name, value);
  return value;
}

std::string stripPadding(std::string text)
{
  while (!text.empty() && text.back() == '\x1a')
    text.pop_back();
  return text;
}

/// The pty pair: socat, and an open descriptor on the control's end so that socat keeps the pair
/// when a peer closes it (the last close of a pty's slave would end socat).
class PtyPair
{
 public:
  PtyPair(const std::string& node_link, const std::string& control_link)
      : socat_({"/usr/bin/socat", "pty,rawer,link=" + node_link, "pty,rawer,link=" + control_link}, "/tmp", "")
  {
    line_log::waitUntilAllExist({node_link, control_link}, 5.0);  // socat makes them
    fd_ = ::open(control_link.c_str(), O_RDWR | O_NOCTTY);
  }
  ~PtyPair()
  {
    if (fd_ >= 0)
      ::close(fd_);
  }
  bool ok() const { return fd_ >= 0; }
  /// Drops the node's NAKs queued at the control while no peer listened.
  void flush() const { ::tcflush(fd_, TCIFLUSH); }
  /// The control punches text itself.
  bool write(const std::string& text) const
  {
    return ::write(fd_, text.data(), text.size()) == static_cast<ssize_t>(text.size());
  }
  /// What the control receives until a whole '%'-framed program has come (or \p seconds passed).
  std::string readProgram(double seconds) const
  {
    std::string got;
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(seconds);
    while (ros::WallTime::now() < deadline)
    {
      const size_t first = got.find('%');
      if (first != std::string::npos && got.find("%\n", first + 1) != std::string::npos)
        break;
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>((deadline - ros::WallTime::now()).toSec() * 1000) + 1) <= 0)
        continue;
      char buffer[512];
      const ssize_t n = ::read(fd_, buffer, sizeof(buffer));
      if (n > 0)
        got.append(buffer, static_cast<size_t>(n));
    }
    return got;
  }

 private:
  Peer socat_;
  int fd_ = -1;
};

/// The program_requests messages of one dnc_node (in \p nh's namespace), in order.
using EventWatch = topic_watch::TopicWatch<ProgramRequestEvent>;

class DncRequestsTest : public ::testing::Test
{
 protected:
  static void SetUpTestSuite()
  {
    pair_ = std::make_unique<PtyPair>(param("link"), param("control_link"));
    text_pair_ = std::make_unique<PtyPair>(param("text_link"), param("text_control_link"));
  }
  static void TearDownTestSuite()
  {
    pair_.reset();
    text_pair_.reset();
  }

  void SetUp() override
  {
    ASSERT_TRUE(pair_->ok() && text_pair_->ok()) << "socat did not make the pty pairs";
    nh_ = ros::NodeHandle(param("namespace"));
    control_ = param("control_link");
    program_dir_ = param("program_dir");
    python_ = param("python_peer");
    states_ = std::make_unique<topic_watch::TopicWatch<cnc_bridge::MachineState>>("state", 50, nh_);
    events_ = std::make_unique<EventWatch>("program_requests", 20, nh_);
    ASSERT_TRUE(events_->waitForPublisher(20)) << "dnc_node never advertised program_requests";
  }

  /// The control punches \p program by XModem (python3-xmodem, or lrzsz sx) and exits 0 once done.
  int punch(const std::string& program, bool by_sx = false)
  {
    const std::string file = dir_.write("punch.nc", program);
    pair_->flush();
    if (by_sx)
    {
      Peer sx({"/usr/bin/sx", file}, dir_.path, control_);
      return sx.wait();
    }
    Peer python({"/usr/bin/python3", python_, "send", "checksum", control_, file}, dir_.path, "");
    return python.wait();
  }

  /// The control receives (the operator pressed RECV): what it stored, or "" if it failed.
  std::string receive()
  {
    const std::string file = dir_.file("received.nc");
    std::remove(file.c_str());
    Peer python({"/usr/bin/python3", python_, "recv", "checksum", control_, file}, dir_.path, "");
    return python.wait() == 0 ? stripPadding(readFile(file)) : "";
  }

  /// The next program_requests message (within \p seconds).
  std::optional<ProgramRequestEvent> nextEvent(double seconds = 20) { return events_->next(seconds); }

  static std::unique_ptr<PtyPair> pair_, text_pair_;
  TempDir dir_{"test_dnc_requests"};
  ros::NodeHandle nh_;
  std::string control_, program_dir_, python_;
  std::unique_ptr<EventWatch> events_;
  std::unique_ptr<topic_watch::TopicWatch<cnc_bridge::MachineState>> states_;
};
std::unique_ptr<PtyPair> DncRequestsTest::pair_;
std::unique_ptr<PtyPair> DncRequestsTest::text_pair_;
}  // namespace

TEST_F(DncRequestsTest, LoadPunchedBySxIsAnsweredWithTheProgramByXmodem)
{
  const std::string program = "%\nO01234 (BRACKET OP1)\nG00 G90 X1. Y2.\nM30\n%\n";
  std::ofstream(program_dir_ + "/O01234.nc") << program;
  ASSERT_EQ(punch("%\nO00001 (LOAD O1234)\nM30\n%\n", true), 0) << "sx could not punch the request";
  EXPECT_EQ(receive(), program);
  const auto event = nextEvent();
  ASSERT_TRUE(event);
  EXPECT_EQ(event->request, "LOAD");
  EXPECT_EQ(event->number, 1234u);
  EXPECT_EQ(event->program, "O01234.nc");
  EXPECT_TRUE(event->success) << event->outcome;
  EXPECT_EQ(event->machine, "haas");
  EXPECT_EQ(event->source, "rs232 " + param("link"));
}

TEST_F(DncRequestsTest, UnknownNumberIsAnsweredWithTheReason)
{
  ASSERT_EQ(punch("%\nO00007 (SEND O4444)\nM30\n%\n"), 0);
  // The answer replaces the operator's request program O00007, and says why.
  EXPECT_EQ(receive(), "%\nO00007 (O04444 NOT FOUND IN PROGRAMS)\nM30\n%\n");
  const auto event = nextEvent();
  ASSERT_TRUE(event);
  EXPECT_EQ(event->request, "SEND");
  EXPECT_EQ(event->number, 4444u);
  EXPECT_FALSE(event->success);
  EXPECT_NE(event->outcome.find("no O04444.nc in " + program_dir_), std::string::npos) << event->outcome;
  EXPECT_NE(event->outcome.find("(O04444 NOT FOUND IN PROGRAMS)"), std::string::npos) << event->outcome;
}

TEST_F(DncRequestsTest, ProtectedNumberIsNotSentButExplained)
{
  std::ofstream(program_dir_ + "/O09010.nc") << "%\nO09010 (PROBE MACRO)\nM99\n%\n";
  ASSERT_EQ(punch("%\nO00002 (LOAD O9010)\nM30\n%\n"), 0);
  const std::string got = receive();
  EXPECT_EQ(got, "%\nO00002 (O09010 PROTECTED - NOT SENT)\nM30\n%\n");
  EXPECT_EQ(got.find("PROBE MACRO"), std::string::npos) << "the protected program reached the control";
  const auto event = nextEvent();
  ASSERT_TRUE(event);
  EXPECT_FALSE(event->success);
  EXPECT_NE(event->outcome.find("~allow_protected_programs"), std::string::npos) << event->outcome;
}

TEST_F(DncRequestsTest, SaveStoresTheNextPunchInProgramDirAndArchiveOnce)
{
  const std::string program = "%\nO05678 (FIXTURE PLATE)\nG00 X0. Y0.\nM30\n%\n";
  cnc_bridge::programs::ProgramArchive archive(param("archive_dir"));
  for (const int round : {1, 2})
  {
    ASSERT_EQ(punch("%\nO00003 (SAVE O5678)\nM30\n%\n"), 0);
    ASSERT_EQ(punch(program, true), 0) << "sx could not punch the program";
    const auto event = nextEvent();
    ASSERT_TRUE(event);
    EXPECT_EQ(event->request, "SAVE");
    EXPECT_TRUE(event->success) << event->outcome;
    EXPECT_EQ(readFile(program_dir_ + "/O05678.nc"), program);
    const auto history = archive.history("O05678.nc");
    ASSERT_EQ(history.size(), 1u) << "round " << round << ": identical content must be kept once";
    EXPECT_EQ(history[0].source.direction, "received");
    EXPECT_EQ(readFile(history[0].path), program);
    if (round == 2)
    {
      EXPECT_NE(event->outcome.find("the archive holds it already"), std::string::npos) << event->outcome;
    }
  }
}

TEST_F(DncRequestsTest, RequestDuringATransferIsReportedNotDropped)
{
  ros::ServiceClient client = nh_.serviceClient<cnc_bridge::ReceiveProgram>("dnc_node/receive_program");
  ASSERT_TRUE(client.waitForExistence(ros::Duration(20)));
  states_->clear();
  auto call = std::async(std::launch::async,
                         [&]
                         {
                           cnc_bridge::ReceiveProgram srv;
                           srv.request.file = "incoming.nc";
                           srv.request.protocol = "xmodem";
                           client.call(srv);
                           return srv.response;
                         });
  ASSERT_TRUE(states_->waitFor(
      [](const auto& states)
      {
        for (const auto& s : states)
          if (s.execution == cnc_bridge::MachineState::EXECUTION_ACTIVE)
            return true;
        return false;
      },
      20))
      << "the receive never started";
  const std::string request = "%\nO00004 (LOAD O1234)\nM30\n%\n";
  ASSERT_EQ(punch(request), 0);
  const auto response = call.get();
  EXPECT_TRUE(response.success) << response.message;
  EXPECT_EQ(readFile(program_dir_ + "/incoming.nc"), request);
  const auto event = nextEvent();
  ASSERT_TRUE(event);
  EXPECT_EQ(event->request, "LOAD");
  EXPECT_EQ(event->number, 1234u);
  EXPECT_FALSE(event->success);
  EXPECT_NE(event->outcome.find("during the transfer receiving incoming.nc"), std::string::npos) << event->outcome;
}

// A control set to XON/XOFF punches text unasked; a LOAD (here: GET) is drip-fed, a refusal answered
// as text.
TEST_F(DncRequestsTest, TextPunchIsDripFedTheProgramOrAnsweredAsText)
{
  EventWatch events("program_requests", 20, ros::NodeHandle(param("text_namespace")));
  ASSERT_TRUE(events.waitForPublisher(20)) << "the text dnc_node never advertised program_requests";
  const std::string program = "%\nO01234 (BRACKET OP2)\nG00 X1. Y2.\nM30\n%\n";
  std::ofstream(param("text_program_dir") + "/O01234.nc") << program;

  // This node's words are LOAD and GET (~request_load_words).
  ASSERT_TRUE(text_pair_->write("%\nO00005 (GET O1234)\nM30\n%\n"));
  EXPECT_EQ(text_pair_->readProgram(20), program);
  const auto served = events.next(20);
  ASSERT_TRUE(served);
  EXPECT_TRUE(served->success) << served->outcome;
  EXPECT_EQ(served->request, "GET");
  EXPECT_EQ(served->number, 1234u);

  ASSERT_TRUE(text_pair_->write("%\r\nO00006 (LOAD O4444)\r\nM30\r\n%\r\n"));
  EXPECT_EQ(text_pair_->readProgram(20), "%\nO00006 (O04444 NOT FOUND IN PROGRAMS)\nM30\n%\n");
  const auto refused = events.next(20);
  ASSERT_TRUE(refused);
  EXPECT_FALSE(refused->success);
  EXPECT_NE(refused->outcome.find("answered as text"), std::string::npos) << refused->outcome;
}

int main(int argc, char** argv)
{
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_dnc_requests");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
