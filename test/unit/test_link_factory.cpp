// The link factory against real peers: a pty for a serial device, a loopback TCP server for a
// network control and for a device server's raw TCP port. Every wait is a blocking accept or read
// with a timeout; nothing sleeps.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/link_factory.h"
#include "cnc_bridge/transport/tcp.h"
#include "temp_dir.h"
#include "testing/pty.h"

using namespace cnc_bridge;
using namespace std::chrono_literals;

namespace
{
SerialSettings lineOn(const std::string& device, unsigned baud = 9600)
{
  SerialSettings serial;
  serial.device = device;
  serial.baud = baud;
  return serial;
}

/// What \p call throws as ConfigError ("" if it does not throw one).
template <class Call>
std::string configError(Call call)
{
  try
  {
    call();
  }
  catch (const ConfigError& e)
  {
    return e.what();
  }
  return "";
}

/// Bytes written on \p from arrive at \p to.
void expectCarries(Transport& from, Transport& to, const std::string& text)
{
  from.write(text, 2000ms);
  std::string got;
  for (int c; got.size() < text.size() && (c = to.readByte(2000ms)) >= 0;)
  {
    got += static_cast<char>(c);
  }
  EXPECT_EQ(got, text);
}
}  // namespace

TEST(LinkFactory, SerialDeviceOpensThePortAndIsNamedByItsLine)
{
  PtyMaster machine;
  const LinkSettings link = LinkSettings::serialLine(lineOn(machine.slavePath(), 115200));
  EXPECT_EQ(link.hardwareId(), machine.slavePath() + "@115200 8N1");
  EXPECT_EQ(link.lockDevice(), machine.slavePath());
  EXPECT_FALSE(link.networked());

  auto port = linkFactory(link)();
  ASSERT_NE(dynamic_cast<SerialLine*>(port.get()), nullptr) << port->describe();
  expectCarries(*port, machine, "Q500\r");
  expectCarries(machine, *port, "STATUS, BUSY\r\n");
}

TEST(LinkFactory, TcpLinkConnectsToHostAndPort)
{
  TcpServer control(0, "127.0.0.1");
  const LinkSettings link = LinkSettings::tcp("127.0.0.1", control.port(), 2000ms);
  EXPECT_EQ(link.hardwareId(), "127.0.0.1:" + std::to_string(control.port()));
  EXPECT_EQ(link.lockDevice(), "") << "a TCP link has no line to share";
  EXPECT_TRUE(link.networked());

  const LinkFactory open = linkFactory(link);
  auto connection = open();
  auto peer = control.accept(2000ms);
  ASSERT_NE(peer, nullptr) << "the factory did not connect to the server";
  EXPECT_EQ(dynamic_cast<SerialLine*>(connection.get()), nullptr) << "a TCP link is not a serial line";
  expectCarries(*connection, *peer, "?Q100\r\n");
  expectCarries(*peer, *connection, ">SERIAL NUMBER, 1234567\r\n");

  // Each call opens a new connection (a reconnection after a failure).
  auto again = open();
  EXPECT_NE(control.accept(2000ms), nullptr);
}

TEST(LinkFactory, SerialPortAtADeviceServerOpensItsTcpPort)
{
  TcpServer device_server(0, "127.0.0.1");
  const std::string url = "tcp://127.0.0.1:" + std::to_string(device_server.port());
  const LinkSettings link = LinkSettings::serialLine(lineOn(url));
  EXPECT_EQ(link.hardwareId(), url + "@9600 8N1");
  EXPECT_EQ(link.lockDevice(), url) << "every program on the server's port shares its lock";
  EXPECT_TRUE(link.networked());

  auto line = linkFactory(link)();
  auto peer = device_server.accept(2000ms);
  ASSERT_NE(peer, nullptr);
  ASSERT_NE(dynamic_cast<SerialLine*>(line.get()), nullptr) << "a device server's port is a serial line";
  expectCarries(*line, *peer, "%\nO01000\n");
}

TEST(LinkFactory, WrongSettingsAreRefusedWhenTheFactoryIsMade)
{
  EXPECT_NE(configError([] { linkFactory(LinkSettings::serialLine(lineOn("telnet2://host:23"))); })
                .find("unknown kind of link"),
            std::string::npos);
  EXPECT_NE(configError([] { linkFactory(LinkSettings::serialLine(lineOn("tcp://host"))); }).find("no port"),
            std::string::npos);
  EXPECT_NE(configError([] { linkFactory(LinkSettings::serialLine(lineOn(""))); }).find("no device"),
            std::string::npos);
  SerialSettings five_stop_bits = lineOn("/dev/ttyUSB0");
  five_stop_bits.stop_bits = 5;
  EXPECT_NE(configError([&] { linkFactory(LinkSettings::serialLine(five_stop_bits)); }).find("stop bits"),
            std::string::npos);
  EXPECT_NE(configError([] { linkFactory(LinkSettings::tcp("", 5051, 1000ms)); }).find("no host"), std::string::npos);
  EXPECT_NE(configError([] { linkFactory(LinkSettings::tcp("10.0.0.5", 0, 1000ms)); }).find("not 0"),
            std::string::npos);
  EXPECT_NE(configError([] { linkFactory(LinkSettings::tcp("10.0.0.5", 5051, 0ms)); }).find("timeout"),
            std::string::npos);
}

TEST(LinkFactory, AnUnreachableLinkFailsWithALinkError)
{
  // A port nobody listens on: the server is closed before the factory connects.
  uint16_t closed_port = 0;
  {
    TcpServer gone(0, "127.0.0.1");
    closed_port = gone.port();
  }
  const LinkFactory open = linkFactory(LinkSettings::tcp("127.0.0.1", closed_port, 2000ms));
  EXPECT_THROW(open(), LinkError);
  const LinkFactory missing = linkFactory(LinkSettings::serialLine(lineOn("/dev/cnc_bridge_no_such_port")));
  EXPECT_THROW(missing(), LinkError);
}

TEST(LinkFactory, ATcpLinkWithAWireTraceRecordsBothDirections)
{
  test::TempDir dir("test_link_factory");
  TcpServer control(0, "127.0.0.1");
  LinkSettings link = LinkSettings::tcp("127.0.0.1", control.port(), 2000ms);
  link.wire_trace.dir = dir.path;
  {
    auto connection = linkFactory(link)();
    auto peer = control.accept(2000ms);
    ASSERT_NE(peer, nullptr);
    expectCarries(*connection, *peer, "?Q100\r\n");
    expectCarries(*peer, *connection, ">SERIAL NUMBER, 1234567\r\n");
  }
  std::vector<std::string> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir.path))
  {
    files.push_back(entry.path().string());
  }
  ASSERT_EQ(files.size(), 1u);
  EXPECT_NE(files[0].find("127.0.0.1_" + std::to_string(control.port())), std::string::npos) << files[0];
  std::ifstream in(files[0]);
  std::string written, read;
  for (const auto& entry : parseWireTrace(in, files[0]))
  {
    (entry.direction == TraceDirection::kWritten ? written : read).append(entry.bytes.begin(), entry.bytes.end());
  }
  EXPECT_EQ(written, "?Q100\r\n");
  EXPECT_EQ(read, ">SERIAL NUMBER, 1234567\r\n");
}
