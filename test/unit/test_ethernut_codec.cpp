// Unit tests of the ethernut codec: byte-exact frames (IEEE-754 binary32, little-endian, worked
// out by hand from the float bit patterns), every row of the opcode table, NaN/inf rejection,
// stream framing across partial and merged reads, and the qCNC settings file.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <sstream>

#include "cnc_bridge/ethernut/protocol.h"
#include "cnc_bridge/ethernut/settings.h"

using namespace cnc_bridge;
using namespace cnc_bridge::ethernut;

TEST(EthernutCodec, CoordinatesAreLittleEndianBinary32)
{
  // 1.5f = 0x3FC00000, -2.25f = 0xC0100000, 100.0f = 0x42C80000, 1.0f = 0x3F800000, 0 = 0.
  const Frame f = encode(makeMessage(Opcode::kCoordinates, 1.5f, -2.25f, 100.0f));
  const Frame expected = {0x00, 0x00, 0xC0, 0x3F, 0x00, 0x00, 0x10, 0xC0, 0x00, 0x00,
                          0xC8, 0x42, 0x00, 0x00, 0x80, 0x3F, 0x00, 0x00, 0x00, 0x00};
  EXPECT_EQ(f, expected);
  const Message m = decode(f.data());
  EXPECT_EQ(m.x, 1.5f);
  EXPECT_EQ(m.y, -2.25f);
  EXPECT_EQ(m.z, 100.0f);
  EXPECT_EQ(m.status, 1.0f);
  EXPECT_EQ(m.error, 0.0f);
}

TEST(EthernutCodec, NextAndAliveResponseFrames)
{
  // NEXT = (200, 30): 200.0f = 0x43480000, 30.0f = 0x41F00000.
  const Frame next = encode(makeMessage(Opcode::kNext));
  const Frame expected_next = {0x00, 0x00, 0xF0, 0x41, 0, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x00, 0x48, 0x43, 0, 0, 0, 0};
  EXPECT_EQ(next, expected_next);
  // Alive response = (200, 999): 999.0f = 0x4479C000.
  const Frame alive = encode(makeMessage(Opcode::kAliveResponse));
  EXPECT_EQ(alive[0], 0x00);
  EXPECT_EQ(alive[1], 0xC0);
  EXPECT_EQ(alive[2], 0x79);
  EXPECT_EQ(alive[3], 0x44);
  // A non-zero error field travels at offset 16.
  Message m = makeMessage(Opcode::kAck);
  m.error = 3.0f;  // 0x40400000
  const Frame with_error = encode(m);
  EXPECT_EQ(with_error[19], 0x40);
  EXPECT_EQ(with_error[18], 0x40);
}

TEST(EthernutCodec, EveryTableRowRoundTrips)
{
  const auto& table = opcodeTable();
  ASSERT_EQ(table.size(), 18u);
  const int expected[18][2] = {{1, -1},   {2, -1},   {3, -1},   {4, -1},    {15, 15},   {15, 6},
                               {15, 9},   {99, 0},   {99, 99},  {99, 199},  {99, 201},  {200, 30},
                               {200, 50}, {200, 60}, {200, 78}, {200, 101}, {200, 199}, {200, 999}};
  for (size_t i = 0; i < table.size(); ++i)
  {
    SCOPED_TRACE(table[i].name);
    EXPECT_EQ(static_cast<size_t>(table[i].opcode), i + 1);
    EXPECT_EQ(table[i].status, expected[i][0]);
    EXPECT_EQ(table[i].x, expected[i][1]);
    const Message m = makeMessage(table[i].opcode, 7.0f, 8.0f, 9.0f);
    EXPECT_EQ(classify(decode(encode(m).data())), table[i].opcode);
    if (table[i].x == kAnyX)
    {
      EXPECT_EQ(m.x, 7.0f);  // coordinate rows carry the data
      EXPECT_EQ(m.z, 9.0f);
    }
    else
    {
      EXPECT_EQ(m.y, 0.0f);
    }
  }
  EXPECT_EQ(rowOf(Opcode::kPauseRequest).response, Opcode::kPauseAchieved);
  EXPECT_EQ(rowOf(Opcode::kAliveRequest).response, Opcode::kAliveResponse);
  EXPECT_TRUE(rowOf(Opcode::kPosition).from_board);
  EXPECT_FALSE(rowOf(Opcode::kKill).from_board);
  EXPECT_STREQ(toString(Opcode::kResend), "RESEND");
}

TEST(EthernutCodec, UnknownOpcodes)
{
  Message m;
  m.status = 200.0f;
  m.x = 31.0f;
  EXPECT_EQ(classify(m), Opcode::kUnknown);
  m.status = 1.5f;  // not a whole number
  EXPECT_EQ(classify(m), Opcode::kUnknown);
  m.status = 0.0f;
  EXPECT_EQ(classify(m), Opcode::kUnknown);
  m.status = 99.0f;
  m.x = 199.5f;
  EXPECT_EQ(classify(m), Opcode::kUnknown);
  EXPECT_THROW(rowOf(Opcode::kUnknown), ProtocolError);
}

TEST(EthernutCodec, NanAndInfinityAreRejectedBothWays)
{
  Message m = makeMessage(Opcode::kCoordinates, 1, 2, 3);
  m.y = std::numeric_limits<float>::quiet_NaN();
  try
  {
    encode(m);
    FAIL() << "NaN encoded";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_NE(std::string(e.what()).find("field y is NaN"), std::string::npos) << e.what();
  }
  Frame f = encode(makeMessage(Opcode::kCoordinates, 1, 2, 3));
  // +inf = 0x7F800000 in the status field.
  f[12] = 0x00;
  f[13] = 0x00;
  f[14] = 0x80;
  f[15] = 0x7F;
  try
  {
    decode(f.data());
    FAIL() << "inf decoded";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_NE(std::string(e.what()).find("field status is infinite"), std::string::npos) << e.what();
  }
}

TEST(EthernutStream, PartialAndMergedReads)
{
  std::vector<uint8_t> bytes;
  for (int i = 0; i < 5; ++i)
  {
    const Frame f = encode(makeMessage(Opcode::kCoordinates, static_cast<float>(i), 0, 0));
    bytes.insert(bytes.end(), f.begin(), f.end());
  }
  // Every split size from 1 byte to all at once yields the same five messages in order.
  for (size_t chunk = 1; chunk <= bytes.size(); ++chunk)
  {
    SCOPED_TRACE(chunk);
    StreamDecoder decoder;
    std::vector<float> xs;
    for (size_t at = 0; at < bytes.size(); at += chunk)
    {
      const size_t n = std::min(chunk, bytes.size() - at);
      ASSERT_EQ(decoder.feed(bytes.data() + at, n), n);
      Message m;
      while (decoder.next(m))
      {
        xs.push_back(m.x);
      }
    }
    EXPECT_EQ(xs, (std::vector<float>{0, 1, 2, 3, 4}));
    EXPECT_EQ(decoder.pending(), 0u);
  }
}

TEST(EthernutStream, BadFrameIsDroppedAndFramingStaysAligned)
{
  Frame bad = encode(makeMessage(Opcode::kNext));
  bad[0] = 0x00;
  bad[1] = 0x00;
  bad[2] = 0xC0;
  bad[3] = 0x7F;  // x = NaN
  const Frame good = encode(makeMessage(Opcode::kResend));
  std::vector<uint8_t> bytes(bad.begin(), bad.end());
  bytes.insert(bytes.end(), good.begin(), good.end());
  bytes.push_back(0x01);  // a partial third frame
  StreamDecoder decoder;
  decoder.feed(bytes.data(), bytes.size());
  Message m;
  EXPECT_THROW(decoder.next(m), ProtocolError);
  ASSERT_TRUE(decoder.next(m));
  EXPECT_EQ(classify(m), Opcode::kResend);
  EXPECT_FALSE(decoder.next(m));
  EXPECT_EQ(decoder.pending(), 1u);
}

TEST(EthernutStream, FeedTakesOnlyWhatFits)
{
  std::vector<uint8_t> lots(20 * 100, 0);
  StreamDecoder decoder;
  const size_t taken = decoder.feed(lots.data(), lots.size());
  EXPECT_LT(taken, lots.size());
  EXPECT_EQ(taken % 20, 0u);
}

TEST(EthernutSettings, ReadsQcncsDocumentedSettings)
{
  std::istringstream in(
      "# qCNC settings\n"
      "TSS\n"
      "INET_ADD|192.168.0.20   # the board\n"
      "INET_PORT|6666\n"
      "INET_DEL|1500 ms\n"
      "PROG_CNCkill|0\n"
      "PROG_LOGP|/tmp/qcnc.log\n"
      "SERIAL_DEV|/dev/ttyS0\n");
  const Settings s = parseSettings(in, "test.tss");
  EXPECT_EQ(*s.address, "192.168.0.20");
  EXPECT_EQ(*s.port, 6666);
  EXPECT_EQ(*s.dead_link_ms, 1500u);
  EXPECT_FALSE(*s.kill_enabled);
  EXPECT_EQ(*s.serial_device, "/dev/ttyS0");
  EXPECT_EQ(s.values.at("PROG_LOGP"), "/tmp/qcnc.log");
}

TEST(EthernutSettings, RejectsBadFiles)
{
  auto error = [](const std::string& text)
  {
    std::istringstream in(text);
    try
    {
      parseSettings(in, "f.tss");
    }
    catch (const ConfigError& e)
    {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error("INET_PORT|6666\n").find("no 'TSS' marker"), std::string::npos);
  EXPECT_NE(error("TSS\nINET_PORT|66x\n").find("f.tss:2: INET_PORT"), std::string::npos);
  EXPECT_NE(error("TSS\nINET_PORT|70000\n").find("INET_PORT"), std::string::npos);
  EXPECT_NE(error("TSS\nPROG_CNCkill|2\n").find("PROG_CNCkill"), std::string::npos);
  EXPECT_NE(error("TSS\njust words\n").find("expected NAME|value"), std::string::npos);
  EXPECT_NE(error("TSS\n|5\n").find("without a name"), std::string::npos);
  EXPECT_NE(error("TSS\nA|b|c\n").find("may not contain"), std::string::npos);
  // TSS only counts as a word of its own outside comments.
  EXPECT_NE(error("# TSS\nINET_PORT|6666\n").find("no 'TSS' marker"), std::string::npos);
  EXPECT_NE(error("TSSX\nINET_PORT|6666\n").find("expected NAME|value"), std::string::npos);
}

TEST(EthernutSettings, TssMarkerMayBeAWordOnALineOrASettingName)
{
  for (const char* text :
       {"qCNC TSS settings\nINET_PORT|6667\n", "INET_PORT|6667\n  TSS  # marker\n", "TSS|1\nINET_PORT|6667\n"})
  {
    std::istringstream in(text);
    Settings s;
    ASSERT_NO_THROW(s = parseSettings(in, "f.tss")) << text;
    EXPECT_EQ(s.port.value_or(0), 6667) << text;
  }
}
