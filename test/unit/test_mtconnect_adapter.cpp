// MTConnect out, without an agent: the SHDR lines a machine's reports make (changes only, the full
// state, UNAVAILABLE when the node loses the machine, an alarm as a FAULT condition), Devices.xml
// read back by the client's own probe parser, and the adapter's server as an agent meets it over
// TCP (full state first, PING/PONG, two agents, an agent that sends garbage is dropped).
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mtconnect/documents.h"
#include "cnc_bridge/mtconnect/shdr.h"
#include "cnc_bridge/mtconnect/shdr_adapter.h"
#include "cnc_bridge/transport/tcp.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mtconnect;

namespace
{
MachineReport running()
{
  MachineReport r;
  r.link_up = true;
  r.view.estop = Tristate::kOff;
  r.view.mode = Mode::kAuto;
  r.view.execution = Execution::kActive;
  r.view.program = "O1234";
  r.view.line = 20;
  r.view.part_count = 41;
  r.view.position = {0.1, 0.2, -0.05};
  r.view.commanded = {0.1, 0.2, -0.05};
  r.view.spindle_rpm = 1200;
  r.view.feed_rate = 0.01;
  r.view.tool = 3;
  r.view.door = "CLOSED";
  return r;
}

std::string joined(const std::vector<std::string>& lines)
{
  std::string out;
  for (const auto& l : lines)
    out += l + "\n";
  return out;
}

/// An agent's side of the connection: reads until \p needle has arrived (or \p within passed).
std::string readUntil(TcpConnection& link, const std::string& needle, std::string& seen,
                      std::chrono::milliseconds within = std::chrono::milliseconds(5000))
{
  const auto deadline = std::chrono::steady_clock::now() + within;
  uint8_t buffer[4096];
  while (seen.find(needle) == std::string::npos && std::chrono::steady_clock::now() < deadline)
  {
    const size_t n = link.read(buffer, sizeof buffer, Milliseconds(100));
    seen.append(reinterpret_cast<const char*>(buffer), n);
  }
  return seen;
}
}  // namespace

TEST(MtconnectShdr, FirstReportGivesEveryItemThenOnlyChanges)
{
  ShdrDevice device("vf2");
  const std::string first = joined(device.update(running()));
  EXPECT_NE(first.find("vf2:avail|AVAILABLE"), std::string::npos) << first;
  EXPECT_NE(first.find("vf2:exec|ACTIVE"), std::string::npos) << first;
  EXPECT_NE(first.find("vf2:Xact|100"), std::string::npos) << first;  // m -> MILLIMETER
  EXPECT_NE(first.find("vf2:Zact|-50"), std::string::npos) << first;
  EXPECT_NE(first.find("vf2:Frate|10"), std::string::npos) << first;  // m/s -> MILLIMETER/SECOND
  EXPECT_NE(first.find("vf2:estop|ARMED"), std::string::npos) << first;
  EXPECT_NE(first.find("vf2:mode|AUTOMATIC"), std::string::npos) << first;
  // The condition on its own line (it takes the rest of the line).
  EXPECT_NE(first.find("\nvf2:system|NORMAL||||\n"), std::string::npos) << first;

  MachineReport next = running();
  next.view.execution = Execution::kReady;
  next.view.part_count = 42;
  const auto lines = device.update(next);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0], "vf2:exec|READY|vf2:partcount|42");
  EXPECT_TRUE(device.update(next).empty());
}

TEST(MtconnectShdr, AlarmIsStoppedWithAFaultConditionCarryingTheWords)
{
  ShdrDevice device("laser");
  device.update(running());
  MachineReport alarm = running();
  alarm.view.execution = Execution::kAlarm;
  alarm.message = "axis 2 | following error\nstopped";
  const std::string text = joined(device.update(alarm));
  EXPECT_NE(text.find("laser:exec|STOPPED"), std::string::npos) << text;
  // A '|' or a line end in the words would cut the line: they become spaces.
  EXPECT_NE(text.find("\nlaser:message||axis 2   following error stopped\n"), std::string::npos) << text;
  EXPECT_NE(text.find("laser:system|FAULT||||axis 2   following error stopped\n"), std::string::npos) << text;
}

TEST(MtconnectShdr, LinkDownMakesEveryItemUnavailable)
{
  ShdrDevice device("mill");
  device.update(running());
  MachineReport down;  // link_up false
  const std::string text = joined(device.update(down));
  for (const char* item : {"avail", "exec", "Xact", "Ycom", "Sspeed", "partcount", "program", "door_state"})
    EXPECT_NE(text.find(std::string("mill:") + item + "|UNAVAILABLE"), std::string::npos) << item << "\n" << text;
  EXPECT_NE(text.find("mill:system|UNAVAILABLE||||"), std::string::npos) << text;
  const std::string full = joined(device.fullState());
  EXPECT_EQ(full.find("mill:avail|AVAILABLE"), std::string::npos) << full;  // no item kept its value
  EXPECT_EQ(full.find("ACTIVE"), std::string::npos) << full;
}

TEST(MtconnectShdr, UnknownFieldsAreUnavailableNotZero)
{
  ShdrDevice device("m");
  MachineReport r;
  r.link_up = true;  // the node reaches the machine, which reports nothing yet
  const std::string text = joined(device.update(r));
  for (const char* item : {"estop", "mode", "exec", "Xact", "Sspeed", "Frate", "partcount", "line", "tool", "program"})
    EXPECT_NE(text.find(std::string("m:") + item + "|UNAVAILABLE"), std::string::npos) << item << "\n" << text;
  // A MESSAGE is two tokens (native code, text), on a line of its own: the reference agent reads
  // nothing after a MESSAGE on its line.
  EXPECT_NE(text.find("\nm:message||UNAVAILABLE\n"), std::string::npos) << text;
}

TEST(MtconnectShdr, TimestampIsTheAgentsFormat)
{
  const auto when = std::chrono::system_clock::time_point(std::chrono::microseconds(1764318300123456LL));
  EXPECT_EQ(shdrTimestamp(when), "2025-11-28T08:25:00.123456Z");
  EXPECT_EQ(shdrLine("T", "a|1"), "T|a|1\n");
}

TEST(MtconnectShdr, DevicesXmlIsAProbeTheClientReads)
{
  const std::string xml = devicesXml({{"haas_vf2", "cell-haas_vf2"}, {"laser", "cell-laser"}});
  const Document doc = parseDocument(xml);
  ASSERT_EQ(doc.devices.size(), 2u);
  const Device& laser = selectDevice(doc, "laser");
  EXPECT_EQ(laser.uuid, "cell-laser");
  // The standard mapping finds every field in the generated device.
  MachineModel model;
  model.setDevice(laser);
  EXPECT_TRUE(model.unmatched().empty()) << model.unmatched().front();
  EXPECT_EQ(model.resolved().at("x_position"), "laser_Xact");
  EXPECT_EQ(model.resolved().at("spindle_speed"), "laser_Sspeed");
}

TEST(MtconnectShdr, DevicesXmlRefusesNamesAnAgentCannotTake)
{
  EXPECT_THROW(devicesXml({{"2mill", "u"}}), ConfigError);
  EXPECT_THROW(devicesXml({{"a b", "u"}}), ConfigError);
  EXPECT_THROW(devicesXml({{"m", "u"}, {"m", "v"}}), ConfigError);
  EXPECT_THROW(devicesXml({}), ConfigError);
}

TEST(MtconnectShdr, AgentConfigNamesEveryDevice)
{
  const std::string cfg = agentConfig({{"a", "ua"}, {"b", "ub"}, {"c", "uc"}}, "Devices.xml", "10.0.0.5", 7878, 5000);
  EXPECT_NE(cfg.find("Device = a\n"), std::string::npos) << cfg;
  EXPECT_NE(cfg.find("AdditionalDevices = b, c\n"), std::string::npos) << cfg;
  EXPECT_NE(cfg.find("Port = 7878\n"), std::string::npos) << cfg;
}

TEST(MtconnectShdr, CellDevicesAreTheCellFilesMachines)
{
  test::TempDir dir("cnc_shdr");
  const auto path =
      dir.write("cell.yaml", "cell: shop\nmachines:\n  - name: vf2\n    position: [0, 0, 0]\n  - name: laser\n");
  const auto devices = cellDevices(path);
  ASSERT_EQ(devices.size(), 2u);
  EXPECT_EQ(devices[0].name, "vf2");
  EXPECT_EQ(devices[1].uuid, "shop-laser");
  EXPECT_THROW(cellDevices(dir.write("empty.yaml", "cell: x\n")), ConfigError);
  EXPECT_THROW(cellDevices(dir.file("missing.yaml")), ConfigError);
}

TEST(MtconnectShdr, ProjectCellFileMakesDevicesXml)
{
  const auto devices = cellDevices(std::string(CNC_SOURCE_DIR) + "/config/cell.yaml");
  ASSERT_GE(devices.size(), 4u);
  EXPECT_EQ(parseDocument(devicesXml(devices)).devices.size(), devices.size());
}

TEST(MtconnectAdapterServer, NewAgentGetsTheFullStateThenChanges)
{
  AdapterSettings settings;
  settings.address = "127.0.0.1";
  settings.port = 0;
  ShdrAdapter adapter(settings, {"vf2", "laser"});
  const auto t0 = std::chrono::system_clock::now();
  adapter.publish("vf2", running(), t0);

  auto agent = TcpConnection::connect("127.0.0.1", adapter.port(), Milliseconds(2000));
  std::string seen;
  readUntil(*agent, "laser:system|", seen);
  // Both devices: vf2 as reported, laser (not reported yet) unavailable; stamped when reported.
  EXPECT_NE(seen.find(shdrTimestamp(t0) + "|vf2:Frate|10|"), std::string::npos) << seen;
  EXPECT_NE(seen.find("laser:avail|UNAVAILABLE"), std::string::npos) << seen;
  EXPECT_NE(seen.find("vf2:system|NORMAL||||\n"), std::string::npos) << seen;

  MachineReport next = running();
  next.view.tool = 7;
  adapter.publish("vf2", next, t0 + std::chrono::seconds(1));
  readUntil(*agent, "vf2:tool|7\n", seen);
  EXPECT_NE(seen.find(shdrTimestamp(t0 + std::chrono::seconds(1)) + "|vf2:tool|7\n"), std::string::npos) << seen;
  EXPECT_THROW(adapter.publish("nobody", next, t0), ConfigError);
}

TEST(MtconnectAdapterServer, PingIsAnsweredWithTheHeartbeat)
{
  AdapterSettings settings;
  settings.address = "127.0.0.1";
  settings.port = 0;
  settings.heartbeat = Milliseconds(5000);
  ShdrAdapter adapter(settings, {"m"});
  auto agent = TcpConnection::connect("127.0.0.1", adapter.port(), Milliseconds(2000));
  std::string seen;
  readUntil(*agent, "m:system|", seen);
  agent->write(std::string("* PING\n"));
  readUntil(*agent, "* PONG", seen);
  EXPECT_NE(seen.find("* PONG 5000\n"), std::string::npos) << seen;
  EXPECT_EQ(adapter.stats().pings, 1u);
}

TEST(MtconnectAdapterServer, TwoAgentsBothGetEachChange)
{
  AdapterSettings settings;
  settings.address = "127.0.0.1";
  settings.port = 0;
  ShdrAdapter adapter(settings, {"m"});
  auto a = TcpConnection::connect("127.0.0.1", adapter.port(), Milliseconds(2000));
  auto b = TcpConnection::connect("127.0.0.1", adapter.port(), Milliseconds(2000));
  std::string seen_a, seen_b;
  readUntil(*a, "m:system|", seen_a);
  readUntil(*b, "m:system|", seen_b);
  ASSERT_EQ(adapter.stats().agents, 2u);
  adapter.publish("m", running(), std::chrono::system_clock::now());
  readUntil(*a, "m:exec|ACTIVE", seen_a);
  readUntil(*b, "m:exec|ACTIVE", seen_b);
  EXPECT_NE(seen_a.find("m:exec|ACTIVE"), std::string::npos);
  EXPECT_NE(seen_b.find("m:exec|ACTIVE"), std::string::npos);
}

TEST(MtconnectAdapterServer, AnAgentSendingAnEndlessLineIsDroppedOthersStay)
{
  AdapterSettings settings;
  settings.address = "127.0.0.1";
  settings.port = 0;
  settings.max_line_bytes = 64;
  ShdrAdapter adapter(settings, {"m"});
  auto good = TcpConnection::connect("127.0.0.1", adapter.port(), Milliseconds(2000));
  auto bad = TcpConnection::connect("127.0.0.1", adapter.port(), Milliseconds(2000));
  std::string seen_good, seen_bad;
  readUntil(*good, "m:system|", seen_good);
  readUntil(*bad, "m:system|", seen_bad);
  bad->write(std::string(200, 'x'));
  // The adapter closes the bad connection: its next read sees the end of the stream.
  uint8_t buffer[256];
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  bool closed = false;
  while (!closed && std::chrono::steady_clock::now() < deadline)
  {
    try
    {
      bad->read(buffer, sizeof buffer, Milliseconds(100));
    }
    catch (const LinkError&)
    {
      closed = true;
    }
  }
  EXPECT_TRUE(closed);
  EXPECT_EQ(adapter.stats().agents_dropped, 1u);
  adapter.publish("m", running(), std::chrono::system_clock::now());
  readUntil(*good, "m:exec|ACTIVE", seen_good);
  EXPECT_NE(seen_good.find("m:exec|ACTIVE"), std::string::npos);
}

TEST(MtconnectAdapterServer, RestartsOnItsPortWhileAnAgentWasConnected)
{
  AdapterSettings settings;
  settings.address = "127.0.0.1";
  settings.port = 0;
  auto adapter = std::make_unique<ShdrAdapter>(settings, std::vector<std::string>{"m"});
  settings.port = adapter->port();
  auto agent = TcpConnection::connect("127.0.0.1", settings.port, Milliseconds(2000));
  std::string seen;
  readUntil(*agent, "m:system|", seen);
  adapter.reset();
  adapter = std::make_unique<ShdrAdapter>(settings, std::vector<std::string>{"m"});
  auto again = TcpConnection::connect("127.0.0.1", settings.port, Milliseconds(2000));
  std::string seen_again;
  readUntil(*again, "m:system|", seen_again);
  EXPECT_NE(seen_again.find("m:avail|UNAVAILABLE"), std::string::npos) << seen_again;
}

TEST(MtconnectAdapterServer, BusyPortIsAClearError)
{
  AdapterSettings settings;
  settings.address = "127.0.0.1";
  settings.port = 0;
  ShdrAdapter first(settings, {"m"});
  settings.port = first.port();
  try
  {
    ShdrAdapter second(settings, {"m"});
    FAIL() << "a second adapter bound the same port";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("~port"), std::string::npos) << e.what();
  }
  settings.address = "not-an-address";
  EXPECT_THROW(ShdrAdapter(settings, {"m"}), ConfigError);
}
