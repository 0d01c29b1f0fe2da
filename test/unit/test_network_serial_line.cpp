// Serial lines at a device server, against a real one: ser2net serves a pty (the control's port,
// held by the test) on raw TCP and on Telnet with COM Port Control (RFC 2217). What the control
// receives is read on the pty; the line settings ser2net applied are read back from the pty's
// termios.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <termios.h>
#include <unistd.h>

#include <numeric>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/network_serial_line.h"
#include "cnc_bridge/transport/serial_line.h"
#include "ser2net_server.h"
#include "temp_dir.h"
#include "testing/pty.h"

namespace cnc_bridge
{
namespace
{
using namespace std::chrono_literals;
using Bytes = std::vector<uint8_t>;

// ---------------------------------------------------------------------------------------------
// The `port` value

TEST(SerialAddress, PathsStayPathsAndUrlsAreTakenApart)
{
  EXPECT_EQ(parseSerialAddress("/dev/ttyUSB0").kind, SerialAddress::Kind::kDevice);
  EXPECT_EQ(parseSerialAddress("/dev/ttyUSB0").device, "/dev/ttyUSB0");
  const auto raw = parseSerialAddress("tcp://nport-7.shop:4001");
  EXPECT_EQ(raw.kind, SerialAddress::Kind::kRawTcp);
  EXPECT_EQ(raw.host, "nport-7.shop");
  EXPECT_EQ(raw.port, 4001);
  const auto telnet = parseSerialAddress("rfc2217://[fd00::7]:2217");
  EXPECT_EQ(telnet.kind, SerialAddress::Kind::kRfc2217);
  EXPECT_EQ(telnet.host, "fd00::7");
  EXPECT_EQ(telnet.port, 2217);
}

TEST(SerialAddress, BadUrlsSayWhatIsWrong)
{
  const std::pair<const char*, const char*> cases[] = {
      {"tcp://10.0.0.5", "no port"},
      {"tcp://10.0.0.5:0", "1..65535"},
      {"tcp://10.0.0.5:70000", "1..65535"},
      {"tcp://10.0.0.5:40x", "1..65535"},
      {"rfc2217://:4001", "no host"},
      {"tcp://admin@10.0.0.5:4001", "host:port only"},
      {"tcp://10.0.0.5:4001/port1", "host:port only"},
      {"telnet://10.0.0.5:23", "unknown kind of link"},
      {"rfc2217://[fd00::7:2217", "[address]:port"},
  };
  for (const auto& [url, expected] : cases)
  {
    SCOPED_TRACE(url);
    try
    {
      parseSerialAddress(url);
      ADD_FAILURE() << "accepted";
    }
    catch (const ConfigError& e)
    {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Against ser2net

SerialSettings lineAt(const std::string& url)
{
  SerialSettings settings;
  settings.device = url;
  settings.baud = 115200;
  return settings;
}

Bytes everyByteValue(size_t repeats)
{
  Bytes bytes(256 * repeats);
  for (size_t i = 0; i < bytes.size(); ++i)
    bytes[i] = static_cast<uint8_t>(i);
  return bytes;
}

/// Reads exactly \p size bytes (each within 2 s of the last) or fewer if they stop coming.
Bytes readAll(Transport& from, size_t size)
{
  Bytes bytes(size);
  bytes.resize(from.readExactly(bytes.data(), size, 2000ms));
  return bytes;
}

/// The termios the pty's slave has now (the settings the server applied to the control's port).
termios ptyTermios(const PtyMaster& pty)
{
  const int fd = ::open(pty.slavePath().c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK);
  termios tio{};
  EXPECT_EQ(::tcgetattr(fd, &tio), 0);
  ::close(fd);
  return tio;
}

class DeviceServer : public ::testing::Test
{
 protected:
  test::TempDir dir{"cnc_ser2net"};
  PtyMaster control;
  test::Ser2netServer server{dir.path, control.slavePath()};

  /// Both ways: every byte value, 0xFF (Telnet's IAC) included, arrives unchanged.
  void expectBytesIntactBothWays(SerialLine& line)
  {
    const Bytes to_control = everyByteValue(8);
    line.write(to_control);
    EXPECT_EQ(readAll(control, to_control.size()), to_control);
    Bytes to_line = everyByteValue(8);
    std::reverse(to_line.begin(), to_line.end());
    control.write(to_line);
    EXPECT_EQ(readAll(line, to_line.size()), to_line);
  }
};

TEST_F(DeviceServer, RawTcpCarriesEveryByteValueBothWays)
{
  auto line = openSerialLine(lineAt(server.rawUrl()));
  expectBytesIntactBothWays(*line);
  EXPECT_NE(line->describe().find("set up on the server"), std::string::npos) << line->describe();
}

TEST_F(DeviceServer, Rfc2217CarriesEveryByteValueBothWays)
{
  auto line = openSerialLine(lineAt(server.rfc2217Url()));
  expectBytesIntactBothWays(*line);
}

TEST_F(DeviceServer, Rfc2217SetsTheControlsPortFromTheNodesSettings)
{
  SerialSettings settings = lineAt(server.rfc2217Url());
  settings.baud = 19200;
  settings.stop_bits = 2;
  settings.flow_control = FlowControl::kRtsCts;
  auto line = openSerialLine(settings);
  termios tio = ptyTermios(control);
  EXPECT_EQ(::cfgetospeed(&tio), B19200);
  EXPECT_TRUE(tio.c_cflag & CSTOPB);
  EXPECT_TRUE(tio.c_cflag & CRTSCTS);
  EXPECT_FALSE(tio.c_iflag & IXON);

  // The drip-feed reads DC1/DC3 itself: none below it, then the configured flow control again.
  line->setFlowControl(FlowControl::kNone);
  tio = ptyTermios(control);
  EXPECT_FALSE(tio.c_cflag & CRTSCTS);
  EXPECT_FALSE(tio.c_iflag & IXON);
  line->applySettings();
  tio = ptyTermios(control);
  EXPECT_TRUE(tio.c_cflag & CRTSCTS);

  const auto reported = static_cast<TelnetSerialLine&>(*line).serverSettings();
  EXPECT_NE(std::find(reported.begin(), reported.end(), "baud rate 19200"), reported.end());
  EXPECT_NE(std::find(reported.begin(), reported.end(), "stop bits 2"), reported.end());
}

TEST_F(DeviceServer, SettingsComeFromTheServerOnRawTcp)
{
  // The server's own line settings (9600 8N1 here) stay whatever this side is configured for.
  SerialSettings settings = lineAt(server.rawUrl());
  settings.stop_bits = 2;
  auto line = openSerialLine(settings);
  line->write(Bytes{'%'});
  ASSERT_EQ(readAll(control, 1), Bytes{'%'});
  const termios tio = ptyTermios(control);
  EXPECT_EQ(::cfgetospeed(&tio), B9600);
  EXPECT_FALSE(tio.c_cflag & CSTOPB);
}

TEST_F(DeviceServer, Rfc2217OnARawPortIsAClearError)
{
  SerialSettings settings = lineAt("rfc2217://127.0.0.1:" + std::to_string(server.raw_port));
  try
  {
    openSerialLine(settings, InputOnOpen::kDiscard, 500ms);
    FAIL() << "opened";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("raw TCP mode (use tcp://"), std::string::npos) << e.what();
  }
}

TEST_F(DeviceServer, NoServerIsAClearError)
{
  server.stop();
  for (const auto& url : {server.rawUrl(), server.rfc2217Url()})
  {
    SCOPED_TRACE(url);
    try
    {
      openSerialLine(lineAt(url));
      ADD_FAILURE() << "opened";
    }
    catch (const LinkError& e)
    {
      EXPECT_NE(std::string(e.what()).find("cannot reach the device server"), std::string::npos) << e.what();
    }
  }
}

TEST_F(DeviceServer, AServerThatGoesAwayFailsAWaitingRead)
{
  for (const bool telnet : {false, true})
  {
    SCOPED_TRACE(telnet ? "rfc2217" : "raw");
    auto line = openSerialLine(lineAt(telnet ? server.rfc2217Url() : server.rawUrl()));
    std::thread power_cut([&] { server.stop(SIGKILL); });
    try
    {
      uint8_t byte;
      line->read(&byte, 1, 10000ms);
      ADD_FAILURE() << "read returned";
    }
    catch (const LinkError& e)
    {
      EXPECT_NE(std::string(e.what()).find("closed the connection or stopped answering"), std::string::npos)
          << e.what();
    }
    power_cut.join();
    server.start();
  }
}

TEST_F(DeviceServer, ASecondClientIsToldAnotherHoldsThePortAndTheFirstKeepsIt)
{
  for (const bool telnet : {false, true})
  {
    SCOPED_TRACE(telnet ? "rfc2217" : "raw");
    const std::string url = telnet ? server.rfc2217Url() : server.rawUrl();
    auto first = openSerialLine(lineAt(url));
    try
    {
      openSerialLine(lineAt(url));
      ADD_FAILURE() << "a second client opened the line";
    }
    catch (const LinkError& e)
    {
      // ser2net's own words, passed on (on raw TCP: over Telnet they may be lost with the reset our
      // next request meets), and what they mean.
      if (!telnet)
      {
        EXPECT_NE(std::string(e.what()).find("saying 'Port already in use'"), std::string::npos) << e.what();
      }
      EXPECT_NE(std::string(e.what()).find("another client holds its port"), std::string::npos) << e.what();
    }
    // The first client's line still carries bytes both ways, and none of the server's message.
    first->write(std::string("G04 P1\n"));
    const Bytes sent = readAll(control, 7);
    EXPECT_EQ(std::string(sent.begin(), sent.end()), "G04 P1\n");
    control.write(std::string("%\n"));
    const Bytes got = readAll(*first, 2);
    EXPECT_EQ(std::string(got.begin(), got.end()), "%\n");
  }
}

TEST_F(DeviceServer, DataTheControlSendsAtOnceIsKeptWhileARawConnectionIsWatched)
{
  // A control that talks as soon as the port opens (a DPRNT line, a punch): its first bytes arrive
  // while the new connection is watched for a refusal, and must reach the reader all the same.
  control.write(std::string("PROBE X1.0\r\n"));
  auto line = openSerialLine(lineAt(server.rawUrl()), InputOnOpen::kKeep);
  const Bytes got = readAll(*line, 12);
  EXPECT_EQ(std::string(got.begin(), got.end()), "PROBE X1.0\r\n");
}

TEST_F(DeviceServer, DiscardInputDropsWhatTheControlSentBeforeAndKeepsWhatFollows)
{
  auto line = openSerialLine(lineAt(server.rfc2217Url()), InputOnOpen::kKeep);
  control.write(std::string("stale reply\r\n"));
  // The stale bytes have reached this side once the next byte the control sends does.
  control.write(std::string("#"));
  Bytes first(14);
  ASSERT_EQ(line->readExactly(first.data(), first.size(), 2000ms), first.size());
  control.write(std::string("more stale"));
  // Its first byte read here: the rest came with it (one write on the pty, one read by the server).
  ASSERT_EQ(readAll(*line, 1), Bytes{'m'});
  line->discardInput();
  control.write(std::string("fresh"));
  const Bytes fresh = readAll(*line, 5);
  EXPECT_EQ(std::string(fresh.begin(), fresh.end()), "fresh");
}
}  // namespace
}  // namespace cnc_bridge
