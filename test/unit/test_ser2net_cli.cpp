// The cnc_dnc tool through a serial device server, as a user runs it: ser2net (ser2net_server.h)
// serves a pty on raw TCP and on RFC 2217; lrzsz `rx` and `sx` (an independent XModem) sit on the
// far side of the line, a relay in this process passing every byte between the server's pty and
// theirs. Programs of every byte value (0xFF, Telnet's IAC, among them) go both ways over both
// kinds. `cnc_dnc doctor` on a device server: the good path, a port of the other mode, no server,
// another client holding the port, each with the words that say what to check.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/serial_line.h"
#include "peer_process.h"
#include "ser2net_server.h"
#include "temp_dir.h"
#include "testing/pty.h"

namespace cnc_bridge
{
namespace
{
using namespace std::chrono_literals;

/// Passes every byte between two pty masters, both ways, until destroyed.
class Relay
{
 public:
  Relay(Transport& a, Transport& b) : a_to_b_([this, &a, &b] { pump(a, b); }), b_to_a_([this, &a, &b] { pump(b, a); })
  {
  }
  ~Relay()
  {
    stop_ = true;
    a_to_b_.join();
    b_to_a_.join();
  }

 private:
  void pump(Transport& from, Transport& to)
  {
    uint8_t buffer[4096];
    while (!stop_)
    {
      try
      {
        const size_t n = from.read(buffer, sizeof buffer, 50ms);
        if (n > 0)
          to.write(buffer, n, 5000ms);
      }
      catch (const Error&)
      {
        return;
      }
    }
  }

  std::atomic<bool> stop_{false};
  std::thread a_to_b_, b_to_a_;
};

struct ToolRun
{
  int status = -1;
  std::string output;  ///< stdout and stderr
};

/// Runs cnc_dnc with \p args (its own timeouts bound it).
ToolRun cncDnc(const std::string& args)
{
  ToolRun run;
  FILE* pipe = ::popen((std::string(CNC_DNC) + " " + args + " 2>&1").c_str(), "r");
  char buffer[4096];
  for (size_t n; (n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0;)
    run.output.append(buffer, n);
  const int status = ::pclose(pipe);
  run.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return run;
}

/// A binary "program" of \p size random bytes with every byte value, 0xFF in runs too (IAC IAC
/// on the wire is one data byte; two in a row are four), and no SUB at the end (XModem's padding).
std::string everyByteValue(size_t size, uint32_t seed)
{
  std::mt19937 random(seed);
  std::string bytes(size, '\0');
  for (size_t i = 0; i < size; ++i)
    bytes[i] = static_cast<char>(i < 512 ? i % 256 : random() % 256);
  bytes.replace(600, 4, "\xff\xff\xff\xff");
  bytes.back() = 'x';
  return bytes;
}

/// What lrzsz rx stored: the program, then SUB padding to the end of its last block.
void expectPaddedCopy(const std::string& got, const std::string& sent)
{
  ASSERT_GE(got.size(), sent.size());
  EXPECT_TRUE(got.compare(0, sent.size(), sent) == 0) << "the bytes differ";
  EXPECT_EQ(got.find_first_not_of('\x1a', sent.size()), std::string::npos) << "more than SUB padding";
}

/// The kinds of server port a test runs over. Each test has a server of its own: ser2net holds a
/// device for a few milliseconds after its connection closed and refuses a connection to the other
/// accepter of the same device meanwhile, so one test uses one accepter.
enum class Kind
{
  kRaw,
  kRfc2217
};

std::string kindName(const ::testing::TestParamInfo<Kind>& info)
{
  return info.param == Kind::kRaw ? "RawTcp" : "Rfc2217";
}

class DeviceServerCli : public ::testing::TestWithParam<Kind>
{
 protected:
  test::TempDir dir{"cnc_ser2net_cli"};
  PtyMaster peer_side;    ///< lrzsz's tty is this pty's slave
  PtyMaster server_side;  ///< ser2net serves this pty's slave
  Relay relay{peer_side, server_side};
  test::Ser2netServer server{dir.path, server_side.slavePath(), "115200n81"};

  std::string url() const { return GetParam() == Kind::kRaw ? server.rawUrl() : server.rfc2217Url(); }

  /// Starts lrzsz \p program on the peer's tty in the test's folder.
  std::unique_ptr<test::Peer> lrzsz(const char* program, const std::string& file)
  {
    return std::make_unique<test::Peer>(std::vector<std::string>{std::string("/usr/bin/") + program, file}, dir.path,
                                        peer_side.slavePath());
  }
};

TEST_P(DeviceServerCli, SendToRxCarriesEveryByteValue)
{
  const std::string program = everyByteValue(5 * 1024 + 77, 5);
  dir.write("binary.bin", program);
  auto rx = lrzsz("rx", "received.bin");
  const ToolRun send = cncDnc("send --port " + url() + " --baud 115200 --mode checksum --binary --timeout 30 " +
                              "--retries 3 " + dir.file("binary.bin"));
  EXPECT_EQ(rx->wait(), 0);
  ASSERT_EQ(send.status, 0) << send.output;
  expectPaddedCopy(test::readFile(dir.file("received.bin")), program);
}

TEST_P(DeviceServerCli, ReceiveFromSxCarriesEveryByteValue)
{
  const std::string program = everyByteValue(4 * 1024 + 5, 7);
  dir.write("from_sx.bin", program);
  const std::string target = dir.file("received.bin");
  auto sx = lrzsz("sx", "from_sx.bin");
  // The waits of a device server's port (xmodem/network_waits.h): the gaps inside a packet from
  // sx through the relay, the server (64 characters at a time) and TCP exceed a cable's 30 ms.
  const ToolRun receive =
      cncDnc("receive --port " + url() + " --baud 115200 --mode checksum --binary --timeout 30 " + target);
  sx->wait();  // reaped; what it delivered is checked below
  ASSERT_EQ(receive.status, 0) << receive.output;
  // --binary keeps XModem's padding: sx pads its last block with SUB.
  expectPaddedCopy(test::readFile(target), program);
}

// ---------------------------------------------------------------------------------------------
// cnc_dnc doctor on a device server

bool says(const ToolRun& run, const std::string& text)
{
  return run.output.find(text) != std::string::npos;
}

// Tests of one kind only use the fixture with the kind they need.
using DoctorOnRfc2217 = DeviceServerCli;
using DoctorOnRawTcp = DeviceServerCli;

TEST_P(DoctorOnRfc2217, ReportsTheNegotiationAndTheSettingsTheServerConfirms)
{
  const ToolRun run = cncDnc("doctor --port " + url() + " --baud 19200 --stop-bits 2");
  EXPECT_EQ(run.status, 0) << run.output;
  EXPECT_TRUE(says(run, "connect: ok")) << run.output;
  EXPECT_TRUE(says(run, "COM Port Control (RFC 2217) and binary transmission accepted")) << run.output;
  EXPECT_TRUE(says(run, "baud rate 19200")) << run.output;
  EXPECT_TRUE(says(run, "stop bits 2")) << run.output;
  EXPECT_TRUE(says(run, "free for a transfer")) << run.output;
}

TEST_P(DoctorOnRawTcp, SaysTheLineIsSetUpOnTheServer)
{
  const ToolRun run = cncDnc("doctor --port " + url() + " --baud 9600");
  EXPECT_EQ(run.status, 0) << run.output;
  EXPECT_TRUE(says(run, "the server's own (raw TCP cannot set or read them)")) << run.output;
  EXPECT_TRUE(says(run, "9600 baud")) << run.output;
}

TEST_P(DeviceServerCli, DoctorOnAPortOfTheOtherModeNamesTheServersPortMode)
{
  const std::string host = "127.0.0.1:";
  if (GetParam() == Kind::kRaw)
  {
    // rfc2217:// to the raw port.
    const ToolRun run = cncDnc("doctor --port rfc2217://" + host + std::to_string(server.raw_port));
    EXPECT_EQ(run.status, 1) << run.output;
    EXPECT_TRUE(says(run, "the server's port mode: rfc2217:// needs the port in RFC 2217")) << run.output;
    EXPECT_TRUE(says(run, "tcp://" + host + std::to_string(server.raw_port))) << run.output;
  }
  else
  {
    // tcp:// to the RFC 2217 port.
    const ToolRun run = cncDnc("doctor --port tcp://" + host + std::to_string(server.rfc2217_port));
    EXPECT_EQ(run.status, 1) << run.output;
    EXPECT_TRUE(says(run, "its port is in Telnet/RFC 2217 mode: use rfc2217://")) << run.output;
  }
}

TEST_P(DeviceServerCli, DoctorWithNoServerNamesAddressAndFirewall)
{
  server.stop();
  const ToolRun run = cncDnc("doctor --port " + url());
  EXPECT_EQ(run.status, 1) << run.output;
  EXPECT_TRUE(says(run, "cannot reach the device server")) << run.output;
  EXPECT_TRUE(says(run, "no firewall between here and it blocks TCP port")) << run.output;
}

TEST_P(DeviceServerCli, DoctorWhileAnotherClientHoldsThePortSaysSo)
{
  SerialSettings settings;
  settings.device = url();
  const auto holder = openSerialLine(settings);
  const ToolRun run = cncDnc("doctor --port " + url());
  EXPECT_EQ(run.status, 1) << run.output;
  EXPECT_TRUE(says(run, "another client may hold the port")) << run.output;
  // The holder's line still works: the refused client took nothing from it. (The relay passes
  // the byte on to the peer's tty, where it is read.)
  const int peer_tty = ::open(peer_side.slavePath().c_str(), O_RDWR | O_NOCTTY);
  ASSERT_GE(peer_tty, 0);
  holder->write(std::string("%"));
  pollfd ready{peer_tty, POLLIN, 0};
  char byte = 0;
  EXPECT_EQ(::poll(&ready, 1, 2000), 1) << server.log();
  EXPECT_EQ(::read(peer_tty, &byte, 1), 1);
  EXPECT_EQ(byte, '%');
  ::close(peer_tty);
}

INSTANTIATE_TEST_SUITE_P(BothKinds, DeviceServerCli, ::testing::Values(Kind::kRaw, Kind::kRfc2217), kindName);
INSTANTIATE_TEST_SUITE_P(Rfc2217, DoctorOnRfc2217, ::testing::Values(Kind::kRfc2217), kindName);
INSTANTIATE_TEST_SUITE_P(RawTcp, DoctorOnRawTcp, ::testing::Values(Kind::kRaw), kindName);
}  // namespace
}  // namespace cnc_bridge
