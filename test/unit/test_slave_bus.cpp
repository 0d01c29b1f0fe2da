// Codecs of the slave bus: the step frames of the universal-CNC paper (docs/protocols/slave_bus.md#source) byte for
// byte, WirePacker frames and CRC-8/MAXIM against published check values, the master's receive state machine fed byte
// by byte and in chunks, the uplink parser raw and framed (with garbage and corruption), and the value encodings.
#include <gtest/gtest.h>

#include <string>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/slave_bus/array_protocol.h"
#include "cnc_bridge/slave_bus/value_codec.h"
#include "cnc_bridge/slave_bus/wire_packer.h"

using namespace cnc_bridge;
using namespace cnc_bridge::slave_bus;
using Bytes = std::vector<uint8_t>;

namespace
{
// Stand-ins for the universal-CNC paper's symbolic bytes x, y, z, a, f, g, h, data.
constexpr uint8_t x = 10, y = 20, z = 30, a = 40, f = 50, g = 60, h = 70, data = 99;

struct Collected
{
  std::vector<StepReceiver::Delivery> deliveries;
  int frames = 0;
};

StepReceiver makeReceiver(Collected& c, size_t bus_size = 8)
{
  return StepReceiver(
      bus_size, [&c](const StepReceiver::Delivery& d) { c.deliveries.push_back(d); }, [&c] { ++c.frames; });
}
}  // namespace

// ---------------------------------------------------------------------------------------------
// CRC-8/MAXIM and WirePacker

TEST(Crc8Maxim, CheckValueOf123456789)
{
  // The catalogue check value of CRC-8/MAXIM (Dallas 1-Wire): 0xA1.
  const std::string check = "123456789";
  EXPECT_EQ(crc8Maxim(reinterpret_cast<const uint8_t*>(check.data()), check.size()), 0xA1);
}

TEST(Crc8Maxim, KnownVectors)
{
  EXPECT_EQ(crc8Maxim(nullptr, 0), 0x00);
  const Bytes one = {0x01};
  EXPECT_EQ(crc8Maxim(one.data(), one.size()), 0x5E);  // table entry 1 of the Dallas CRC table
  const Bytes ff = {0xFF};
  EXPECT_EQ(crc8Maxim(ff.data(), ff.size()), 0x35);  // table entry 255
  // Maxim application note 27 example: a DS1820-style ROM 02 1C B8 01 00 00 00 has CRC 0xA2, and
  // the CRC over the ROM including its CRC byte is 0.
  const Bytes rom = {0x02, 0x1C, 0xB8, 0x01, 0x00, 0x00, 0x00};
  EXPECT_EQ(crc8Maxim(rom.data(), rom.size()), 0xA2);
  Bytes with_crc = rom;
  with_crc.push_back(0xA2);
  EXPECT_EQ(crc8Maxim(with_crc.data(), with_crc.size()), 0x00);
}

TEST(Crc8Maxim, ChainsAcrossCalls)
{
  const std::string check = "123456789";
  const auto* p = reinterpret_cast<const uint8_t*>(check.data());
  EXPECT_EQ(crc8Maxim(p + 4, 5, crc8Maxim(p, 4)), 0xA1);
}

TEST(WirePacker, PacksStartLengthDataCrcEnd)
{
  const Bytes payload = {0x31, 0x32, 0x33};
  const Bytes frame = WirePacker::pack(payload);
  // length counts the whole frame: 3 data + 4; CRC over [0x07, 0x31, 0x32, 0x33].
  const Bytes crc_input = {0x07, 0x31, 0x32, 0x33};
  const Bytes expected = {0x02, 0x07, 0x31, 0x32, 0x33, crc8Maxim(crc_input.data(), crc_input.size()), 0x04};
  EXPECT_EQ(frame, expected);
  EXPECT_EQ(WirePacker::unpack(frame), payload);
}

TEST(WirePacker, EmptyPayloadIsFourBytes)
{
  const Bytes length = {0x04};
  const Bytes expected = {0x02, 0x04, crc8Maxim(length.data(), 1), 0x04};
  EXPECT_EQ(WirePacker::pack(Bytes{}), expected);
  EXPECT_TRUE(WirePacker::unpack(expected).empty());
}

TEST(WirePacker, LargestFrameAndTooLarge)
{
  Bytes payload(WirePacker::kMaxData, 0x02);  // start bytes inside the data are fine: no escaping
  const auto frame = WirePacker::pack(payload);
  EXPECT_EQ(frame.size(), 255u);
  EXPECT_EQ(frame[1], 255);
  EXPECT_EQ(WirePacker::unpack(frame), payload);
  payload.push_back(0);
  EXPECT_THROW(WirePacker::pack(payload), ProtocolError);
}

TEST(WirePacker, UnpackNamesWhatIsWrong)
{
  const Bytes good = WirePacker::pack(Bytes{1, 2, 3});
  auto expectError = [](Bytes frame, const std::string& word)
  {
    try
    {
      WirePacker::unpack(frame);
      FAIL() << "accepted a bad frame";
    }
    catch (const ProtocolError& e)
    {
      EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
    }
  };
  Bytes bad = good;
  bad[0] = 0x03;
  expectError(bad, "starts");
  bad = good;
  bad[1] = 6;
  expectError(bad, "length");
  bad = good;
  bad.back() = 0x05;
  expectError(bad, "ends");
  bad = good;
  bad[3] ^= 0x01;
  expectError(bad, "CRC");
  expectError(Bytes{0x02, 0x04}, "shorter");
}

TEST(WireStreamUnpacker, FindsFramesInChunksAndAcrossGarbage)
{
  const Bytes a1 = WirePacker::pack(Bytes{1, 2});
  const Bytes a2 = WirePacker::pack(Bytes{0x02, 0x04, 0x02});  // framing bytes inside the data
  Bytes stream = {0xFF, 0x00, 0x04};                           // line noise before the first frame
  stream.insert(stream.end(), a1.begin(), a1.end());
  stream.insert(stream.end(), {0x02, 0x09, 0x11});  // a torn frame: start, length 9, one byte
  stream.insert(stream.end(), a2.begin(), a2.end());
  stream.insert(stream.end(), {0x02, 0x02});  // a start byte with an impossible length
  stream.insert(stream.end(), a1.begin(), a1.end());

  for (size_t chunk : {size_t(1), size_t(2), size_t(5), stream.size()})
  {
    WireStreamUnpacker unpacker;
    std::vector<Bytes> frames;
    for (size_t i = 0; i < stream.size(); i += chunk)
    {
      for (auto& frame : unpacker.feed(stream.data() + i, std::min(chunk, stream.size() - i)))
      {
        frames.push_back(frame);
      }
    }
    ASSERT_EQ(frames.size(), 3u) << "chunk " << chunk;
    EXPECT_EQ(frames[0], (Bytes{1, 2}));
    EXPECT_EQ(frames[1], (Bytes{0x02, 0x04, 0x02}));
    EXPECT_EQ(frames[2], (Bytes{1, 2}));
    EXPECT_EQ(unpacker.stats().frames, 3u);
    EXPECT_EQ(unpacker.pending(), 0u);
    EXPECT_GT(unpacker.stats().garbage_bytes, 3u);
  }
}

TEST(WireStreamUnpacker, CorruptedFrameIsCountedAndTheNextOneFound)
{
  Bytes bad = WirePacker::pack(Bytes{7, 7, 7});
  bad[3] ^= 0x40;
  const Bytes good = WirePacker::pack(Bytes{8});
  Bytes stream = bad;
  stream.insert(stream.end(), good.begin(), good.end());
  WireStreamUnpacker unpacker;
  const auto frames = unpacker.feed(stream.data(), stream.size());
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(frames[0], Bytes{8});
  EXPECT_EQ(unpacker.stats().crc_errors, 1u);
}

TEST(WireStreamUnpacker, ResyncAbandonsATornFrameAndFindsWhatItHid)
{
  WireStreamUnpacker unpacker;
  // A stray start byte with length 200 would hold everything behind it until 200 bytes arrived.
  Bytes stream = {0x02, 200, 1, 3};
  const Bytes good = WirePacker::pack(Bytes{5});
  stream.insert(stream.end(), good.begin(), good.end());
  EXPECT_TRUE(unpacker.feed(stream.data(), stream.size()).empty());
  EXPECT_EQ(unpacker.pending(), stream.size());
  // The line went quiet: the candidate is torn.
  const auto frames = unpacker.resync();
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(frames[0], Bytes{5});
  EXPECT_EQ(unpacker.pending(), 0u);
  EXPECT_EQ(unpacker.stats().framing_errors, 1u);
  // A torn frame with nothing behind it is simply dropped.
  const Bytes torn = {0x02, 0x08, 1};
  EXPECT_TRUE(unpacker.feed(torn.data(), torn.size()).empty());
  EXPECT_TRUE(unpacker.resync().empty());
  EXPECT_EQ(unpacker.pending(), 0u);
  EXPECT_EQ(unpacker.feed(good.data(), good.size()).size(), 1u);
}

// The released ESP32_I2C_Slave library (the one the universal-CNC paper cites) computes its CRC over the data
// only: its WireCrc::update() starts from the member seed (0) and never stores the result of
// calc(&length, 1). Vectors worked by hand from its code: CRC-8/MAXIM of 31 32 33 is 0x95; over
// 07 31 32 33 (the documented format, length first) it is 0x13.
TEST(WireCrc, LibraryVariantCoversTheDataOnly)
{
  const Bytes data = {0x31, 0x32, 0x33};
  EXPECT_EQ(crc8Maxim(data.data(), data.size()), 0x95);
  const Bytes with_length = {0x07, 0x31, 0x32, 0x33};
  EXPECT_EQ(crc8Maxim(with_length.data(), with_length.size()), 0x13);

  const auto library = WireFormat::of(WireCrc::kLibrary);
  EXPECT_EQ(WirePacker::pack(data, library), (Bytes{0x02, 0x07, 0x31, 0x32, 0x33, 0x95, 0x04}));
  EXPECT_EQ(WirePacker::pack(data), (Bytes{0x02, 0x07, 0x31, 0x32, 0x33, 0x13, 0x04}));  // spec is the default
  EXPECT_EQ(WirePacker::unpack(Bytes{0x02, 0x07, 0x31, 0x32, 0x33, 0x95, 0x04}, library), data);
  // An empty frame of the library has CRC 0 (no data), the spec's the CRC of its length byte.
  EXPECT_EQ(WirePacker::pack(Bytes{}, library), (Bytes{0x02, 0x04, 0x00, 0x04}));
  // Each side refuses the other's frames, naming what its CRC covers.
  try
  {
    WirePacker::unpack(Bytes{0x02, 0x07, 0x31, 0x32, 0x33, 0x95, 0x04});
    FAIL() << "the spec reading accepted the library's CRC";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_NE(std::string(e.what()).find("length and data"), std::string::npos) << e.what();
  }
  EXPECT_THROW(WirePacker::unpack(Bytes{0x02, 0x07, 0x31, 0x32, 0x33, 0x13, 0x04}, library), ProtocolError);
  EXPECT_EQ(parseWireCrc("spec"), WireCrc::kSpec);
  EXPECT_EQ(parseWireCrc("library"), WireCrc::kLibrary);
  EXPECT_THROW(parseWireCrc("data_only"), ConfigError);
}

TEST(WireFormat, LibraryFramesStopAtItsBufferAndLongerPayloadsAreRefused)
{
  // PACKER_BUFFER_LENGTH and UNPACKER_BUFFER_LENGTH are 128 in the library: 124 bytes of data.
  EXPECT_EQ(WireFormat::of(WireCrc::kLibrary).max_data, 124u);
  EXPECT_EQ(WireFormat::of(WireCrc::kSpec).max_data, 251u);
  EXPECT_EQ(WireFormat::of(WireCrc::kLibrary, 200).max_data, 200u);  // a firmware with larger buffers
  EXPECT_THROW(WireFormat::of(WireCrc::kSpec, 252), ConfigError);
  const auto library = WireFormat::of(WireCrc::kLibrary);
  EXPECT_EQ(WirePacker::pack(Bytes(124, 7), library).size(), 128u);
  try
  {
    WirePacker::pack(Bytes(125, 7), library);
    FAIL() << "packed 125 bytes into a 124-byte frame";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_NE(std::string(e.what()).find("at most 124"), std::string::npos) << e.what();
  }
  // A frame longer than the configured limit is refused on unpacking too.
  EXPECT_THROW(WirePacker::unpack(WirePacker::pack(Bytes(125, 7)), library), ProtocolError);
}

TEST(WireStreamUnpacker, LibraryModeRejectsALengthOverItsBufferAtOnce)
{
  const auto library = WireFormat::of(WireCrc::kLibrary);
  WireStreamUnpacker unpacker(library);
  // A stray start byte with length 200: no library frame is that long, so the good frame behind it
  // is found at once, with no silence needed.
  Bytes stream = {0x02, 200, 1, 3};
  const Bytes good = WirePacker::pack(Bytes{5}, library);
  stream.insert(stream.end(), good.begin(), good.end());
  const auto frames = unpacker.feed(stream.data(), stream.size());
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(frames[0], Bytes{5});
  EXPECT_EQ(unpacker.stats().framing_errors, 1u);
  EXPECT_EQ(unpacker.pending(), 0u);
  // A spec frame is a CRC error to a library receiver.
  const Bytes spec = WirePacker::pack(Bytes{5});
  EXPECT_TRUE(unpacker.feed(spec.data(), spec.size()).empty());
  EXPECT_EQ(unpacker.stats().crc_errors, 1u);
}

// ---------------------------------------------------------------------------------------------
// Step frames (PC -> master)

TEST(EncodeStep, PaperExampleThreeSlaves)
{
  // The universal-CNC paper: [3, 2, x, y, 1, a, 3, f, g, h]
  const StepPayloads payloads = {{x, y}, {a}, {f, g, h}};
  EXPECT_EQ(encodeStep(payloads), (Bytes{3, 2, x, y, 1, a, 3, f, g, h}));
}

TEST(EncodeStep, PaperExampleEightSlavesXYZ)
{
  // The universal-CNC paper: [8,1,x,1,y,1,z,0,0,0,0,0] -- x, y, z to slaves 1..3, nothing to the other five.
  const StepPayloads payloads = {{x}, {y}, {z}, {}, {}, {}, {}, {}};
  EXPECT_EQ(encodeStep(payloads), (Bytes{8, 1, x, 1, y, 1, z, 0, 0, 0, 0, 0}));
}

TEST(EncodeStep, PaperExampleSlaveSixGetsData)
{
  // The universal-CNC paper: [8,1,x,1,y,1,z,0,0,1,data,0,0] -- slave 6 gets data.
  const StepPayloads payloads = {{x}, {y}, {z}, {}, {}, {data}, {}, {}};
  EXPECT_EQ(encodeStep(payloads), (Bytes{8, 1, x, 1, y, 1, z, 0, 0, 1, data, 0, 0}));
}

TEST(EncodeStep, RefusesWhatTheMasterCannotTake)
{
  EXPECT_THROW(encodeStep({}), ProtocolError);                            // no slaves
  EXPECT_THROW(encodeStep(StepPayloads(kMaxSlaves + 1)), ProtocolError);  // too many slaves
  EXPECT_NO_THROW(encodeStep(StepPayloads(kMaxSlaves)));
  EXPECT_THROW(encodeStep({Bytes(kMaxPayload + 1, 1)}), ProtocolError);  // payload too long
  EXPECT_EQ(encodeStep({Bytes(kMaxPayload, 1)}).size(), kMaxPayload + 2);
}

TEST(EncodeStep, FramedWrapsTheSameBytesInAWirePackerFrame)
{
  const StepPayloads payloads = {{x, y}, {a}, {f, g, h}};
  const auto framed = encodeStepForLink(payloads, Framing::kFramed);
  EXPECT_EQ(WirePacker::unpack(framed), (Bytes{3, 2, x, y, 1, a, 3, f, g, h}));
  EXPECT_EQ(encodeStepForLink(payloads, Framing::kRaw), encodeStep(payloads));
  // 32 slaves with 7 bytes each make a 257-byte raw frame: too big for one WirePacker frame.
  EXPECT_THROW(encodeStepForLink(StepPayloads(32, Bytes(7, 1)), Framing::kFramed), ProtocolError);
  EXPECT_NO_THROW(encodeStepForLink(StepPayloads(31, Bytes(7, 1)), Framing::kFramed));  // 249 bytes
}

TEST(EncodeStep, PayloadsAndFramedStepsStopAtTheMastersFrameSize)
{
  const auto library = WireFormat::of(WireCrc::kLibrary);
  EXPECT_EQ(encodeStepForLink({Bytes(124, 1)}, Framing::kRaw, library).size(), 126u);
  try
  {
    encodeStepForLink({{}, Bytes(125, 1)}, Framing::kRaw, library);
    FAIL() << "a 125-byte payload went to a master whose I2C frames carry 124";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_NE(std::string(e.what()).find("slave 2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("at most 124"), std::string::npos) << e.what();
  }
  // Framed, the whole step is one frame: 8 slaves with 14 bytes each are 121 bytes, 15 are 129.
  const auto framed = encodeStepForLink(StepPayloads(8, Bytes(14, 1)), Framing::kFramed, library);
  EXPECT_EQ(WirePacker::unpack(framed, library).size(), 121u);
  EXPECT_THROW(encodeStepForLink(StepPayloads(8, Bytes(15, 1)), Framing::kFramed, library), ProtocolError);
}

// ---------------------------------------------------------------------------------------------
// The master's receive state machine

TEST(StepReceiver, PaperExampleByteByByte)
{
  Collected c;
  auto receiver = makeReceiver(c, 3);
  const Bytes frame = {3, 2, x, y, 1, a, 3, f, g, h};
  std::vector<StepReceiver::State> states;
  for (uint8_t byte : frame)
  {
    receiver.feed(byte);
    states.push_back(receiver.state());
  }
  using S = StepReceiver::State;
  EXPECT_EQ(states, (std::vector<S>{S::kSlaveLen, S::kSlaveBytes, S::kSlaveBytes, S::kSlaveLen, S::kSlaveBytes,
                                    S::kSlaveLen, S::kSlaveBytes, S::kSlaveBytes, S::kSlaveBytes, S::kSlavesNum}));
  ASSERT_EQ(c.deliveries.size(), 3u);
  EXPECT_EQ(c.deliveries[0].address, 1);
  EXPECT_EQ(c.deliveries[0].payload, (Bytes{x, y}));
  EXPECT_EQ(c.deliveries[1].address, 2);
  EXPECT_EQ(c.deliveries[1].payload, (Bytes{a}));
  EXPECT_EQ(c.deliveries[2].address, 3);
  EXPECT_EQ(c.deliveries[2].payload, (Bytes{f, g, h}));
  EXPECT_TRUE(c.deliveries[2].known);
  EXPECT_EQ(c.frames, 1);
}

TEST(StepReceiver, SlaveSixGetsDataAndZeroLengthsDeliverNothing)
{
  Collected c;
  auto receiver = makeReceiver(c);
  const Bytes frame = {8, 1, x, 1, y, 1, z, 0, 0, 1, data, 0, 0};
  receiver.feed(frame.data(), frame.size());
  ASSERT_EQ(c.deliveries.size(), 4u);
  EXPECT_EQ(c.deliveries[3].address, 6);
  EXPECT_EQ(c.deliveries[3].payload, Bytes{data});
  EXPECT_EQ(c.frames, 1);
  EXPECT_TRUE(receiver.idle());
}

TEST(StepReceiver, AllZeroLengthsAndEmptyFrames)
{
  Collected c;
  auto receiver = makeReceiver(c);
  const Bytes frames = {8, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 1, 5};
  receiver.feed(frames.data(), frames.size());
  // the 8-slave frame with nothing, an empty frame (count 0), then [2, 0, 1, 5]
  EXPECT_EQ(c.frames, 3);
  ASSERT_EQ(c.deliveries.size(), 1u);
  EXPECT_EQ(c.deliveries[0].address, 2);
  EXPECT_EQ(c.deliveries[0].payload, Bytes{5});
}

TEST(StepReceiver, ChunksOfEverySizeGiveTheSameResult)
{
  Bytes stream;
  for (int i = 0; i < 5; ++i)
  {
    const auto frame = encodeStep({{x, static_cast<uint8_t>(i)}, {}, {a}, Bytes(40, static_cast<uint8_t>(i))});
    stream.insert(stream.end(), frame.begin(), frame.end());
  }
  Collected whole;
  auto reference = makeReceiver(whole, 4);
  reference.feed(stream.data(), stream.size());
  ASSERT_EQ(whole.frames, 5);
  ASSERT_EQ(whole.deliveries.size(), 15u);
  for (size_t chunk = 1; chunk <= 17; ++chunk)
  {
    Collected c;
    auto receiver = makeReceiver(c, 4);
    for (size_t i = 0; i < stream.size(); i += chunk)
    {
      receiver.feed(stream.data() + i, std::min(chunk, stream.size() - i));
    }
    EXPECT_EQ(c.frames, 5) << "chunk " << chunk;
    ASSERT_EQ(c.deliveries.size(), whole.deliveries.size()) << "chunk " << chunk;
    for (size_t i = 0; i < c.deliveries.size(); ++i)
    {
      EXPECT_EQ(c.deliveries[i].address, whole.deliveries[i].address);
      EXPECT_EQ(c.deliveries[i].payload, whole.deliveries[i].payload);
    }
  }
}

TEST(StepReceiver, TooManySlavesStayInSyncAndAreMarkedUnknown)
{
  Collected c;
  auto receiver = makeReceiver(c, 3);
  const Bytes frame = {5, 1, x, 0, 0, 1, data, 2, y, z};
  receiver.feed(frame.data(), frame.size());
  EXPECT_EQ(c.frames, 1);
  ASSERT_EQ(c.deliveries.size(), 3u);
  EXPECT_TRUE(c.deliveries[0].known);
  EXPECT_EQ(c.deliveries[1].address, 4);
  EXPECT_FALSE(c.deliveries[1].known);
  EXPECT_EQ(c.deliveries[2].address, 5);
  EXPECT_FALSE(c.deliveries[2].known);
  // The next frame parses normally.
  const Bytes next = {1, 1, a};
  receiver.feed(next.data(), next.size());
  EXPECT_EQ(c.frames, 2);
  EXPECT_EQ(c.deliveries.back().payload, Bytes{a});
}

TEST(StepReceiver, TruncatedFrameIsHeldUntilResetThenTheNextFrameParses)
{
  Collected c;
  auto receiver = makeReceiver(c, 3);
  const Bytes torn = {3, 2, x, y, 1};  // slave 2's length arrived, its byte did not
  receiver.feed(torn.data(), torn.size());
  EXPECT_EQ(receiver.state(), StepReceiver::State::kSlaveBytes);
  EXPECT_EQ(c.deliveries.size(), 1u);  // slave 1 got its payload as soon as it was complete
  EXPECT_EQ(c.frames, 0);
  EXPECT_TRUE(receiver.reset());
  EXPECT_FALSE(receiver.reset());
  const Bytes frame = {3, 0, 1, a, 0};
  receiver.feed(frame.data(), frame.size());
  EXPECT_EQ(c.frames, 1);
  EXPECT_EQ(c.deliveries.back().address, 2);
  EXPECT_EQ(c.deliveries.back().payload, Bytes{a});
}

TEST(StepReceiver, EncodeThenReceiveRoundTrips)
{
  StepPayloads payloads;
  for (int i = 0; i < 20; ++i)
  {
    payloads.push_back(Bytes(static_cast<size_t>(i % 4 == 0 ? 0 : i * 3), static_cast<uint8_t>(i)));
  }
  Collected c;
  auto receiver = makeReceiver(c, payloads.size());
  const auto frame = encodeStep(payloads);
  receiver.feed(frame.data(), frame.size());
  EXPECT_EQ(c.frames, 1);
  size_t k = 0;
  for (size_t i = 0; i < payloads.size(); ++i)
  {
    if (payloads[i].empty())
    {
      continue;
    }
    ASSERT_LT(k, c.deliveries.size());
    EXPECT_EQ(c.deliveries[k].address, i + 1);
    EXPECT_EQ(c.deliveries[k].payload, payloads[i]);
    ++k;
  }
  EXPECT_EQ(k, c.deliveries.size());
}

// ---------------------------------------------------------------------------------------------
// Uplink (master -> PC)

TEST(Uplink, RawRecordsAreAddressLengthPayload)
{
  EXPECT_EQ(encodeUplink({3, {1, 2, 3}}, Framing::kRaw), (Bytes{3, 3, 1, 2, 3}));
  EXPECT_EQ(encodeUplink({5, {}}, Framing::kRaw), (Bytes{5, 0}));
  EXPECT_EQ(WirePacker::unpack(encodeUplink({3, {1, 2}}, Framing::kFramed)), (Bytes{3, 1, 2}));
}

TEST(Uplink, RawParserInChunks)
{
  const Bytes stream = {1, 2, 0xAA, 0xBB, 6, 0, 0, 2, 2, 7, 3, 1, 9};
  for (size_t chunk = 1; chunk <= stream.size(); ++chunk)
  {
    UplinkParser parser(Framing::kRaw, 8);
    std::vector<UplinkRecord> records;
    for (size_t i = 0; i < stream.size(); i += chunk)
    {
      for (auto& r : parser.feed(stream.data() + i, std::min(chunk, stream.size() - i)))
      {
        records.push_back(r);
      }
    }
    ASSERT_EQ(records.size(), 4u) << "chunk " << chunk;
    EXPECT_EQ(records[0].address, 1);
    EXPECT_EQ(records[0].payload, (Bytes{0xAA, 0xBB}));
    EXPECT_EQ(records[1].address, 6);
    EXPECT_TRUE(records[1].payload.empty());
    EXPECT_EQ(records[2].address, 0);  // master status: it has no slave 7
    EXPECT_EQ(records[2].payload, (Bytes{static_cast<uint8_t>(MasterStatus::kNoSuchSlave), 7}));
    EXPECT_EQ(records[3].address, 3);
    EXPECT_EQ(records[3].payload, Bytes{9});
  }
}

TEST(Uplink, FramedParserSkipsAMasterStatusWithoutItsCode)
{
  // Found by fuzz_slave_bus_uplink: a well-formed frame carrying only address 0.
  UplinkParser parser(Framing::kFramed, 8);
  Bytes stream = WirePacker::pack(Bytes{0});
  const Bytes good = WirePacker::pack(Bytes{3, 7});
  stream.insert(stream.end(), good.begin(), good.end());
  const auto records = parser.feed(stream.data(), stream.size());
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(records[0].address, 3);
  EXPECT_EQ(records[0].payload, Bytes{7});
}

TEST(Uplink, RawParserSkipsImpossibleAddressesAndEmptyStatus)
{
  UplinkParser parser(Framing::kRaw, 8);
  const Bytes stream = {0xEE, 0x09, 2, 1, 5, 0, 0, 1, 1};
  const auto records = parser.feed(stream.data(), stream.size());
  ASSERT_EQ(records.size(), 2u);
  EXPECT_EQ(records[0].address, 2);
  EXPECT_EQ(records[0].payload, Bytes{5});
  // [0, 0] cannot be a status record (no code): the second 0 starts [0, 1, 1] = bad frame.
  EXPECT_EQ(records[1].address, 0);
  EXPECT_EQ(records[1].payload, Bytes{1});
  EXPECT_EQ(parser.stats().garbage_bytes, 3u);
}

TEST(Uplink, RawResyncDropsATornRecord)
{
  UplinkParser parser(Framing::kRaw, 8);
  const Bytes torn = {3, 4, 1};
  EXPECT_TRUE(parser.feed(torn.data(), torn.size()).empty());
  EXPECT_EQ(parser.pending(), 3u);
  EXPECT_TRUE(parser.resync().empty());
  const Bytes next = {3, 1, 7};
  const auto records = parser.feed(next.data(), next.size());
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(records[0].payload, Bytes{7});
}

TEST(Uplink, FramedParserResynchronisesAfterGarbageAndCorruption)
{
  Bytes stream = {0x13, 0x02, 0x37};  // garbage, including a start byte with a nonsense length
  const auto r1 = encodeUplink({1, {0x10, 0x20}}, Framing::kFramed);
  auto r2 = encodeUplink({2, {0x30}}, Framing::kFramed);
  r2[3] ^= 0x01;  // corrupted on the line
  const auto r3 = encodeUplink({3, {}}, Framing::kFramed);
  for (const Bytes* part : {&r1, static_cast<const Bytes*>(&r2), &r3})
  {
    stream.insert(stream.end(), part->begin(), part->end());
    stream.insert(stream.end(), {0x55, 0x04});  // more noise between frames
  }
  for (size_t chunk : {size_t(1), size_t(3), stream.size()})
  {
    UplinkParser parser(Framing::kFramed, 8);
    std::vector<UplinkRecord> records;
    for (size_t i = 0; i < stream.size(); i += chunk)
    {
      for (auto& r : parser.feed(stream.data() + i, std::min(chunk, stream.size() - i)))
      {
        records.push_back(r);
      }
    }
    // The stray [0x02, 0x37] waits for 55 bytes that never come; the silence after the burst
    // abandons it and the records it held back come out.
    EXPECT_GT(parser.pending(), 0u);
    for (auto& r : parser.resync())
    {
      records.push_back(r);
    }
    ASSERT_EQ(records.size(), 2u) << "chunk " << chunk;
    EXPECT_EQ(records[0].address, 1);
    EXPECT_EQ(records[0].payload, (Bytes{0x10, 0x20}));
    EXPECT_EQ(records[1].address, 3);
    EXPECT_TRUE(records[1].payload.empty());
    EXPECT_EQ(parser.stats().crc_errors, 1u);
    EXPECT_EQ(parser.stats().records, 2u);
  }
}

TEST(Uplink, FramedRecordWithNoAddressIsNotDelivered)
{
  UplinkParser parser(Framing::kFramed, 8);
  const auto empty = WirePacker::pack(Bytes{});
  const auto far = WirePacker::pack(Bytes{100, 1});
  EXPECT_TRUE(parser.feed(empty.data(), empty.size()).empty());
  EXPECT_TRUE(parser.feed(far.data(), far.size()).empty());
  EXPECT_EQ(parser.stats().records, 0u);
  EXPECT_EQ(parser.stats().framing_errors, 2u);
}

// ---------------------------------------------------------------------------------------------
// Value encodings

TEST(ValueCodec, PaperHundredsForm)
{
  // The universal-CNC paper's slave reads recived[0]*100 + recived[1]: 1234 travels as [12, 34].
  EXPECT_EQ(encodeValues({1234, 7, 25599}, Encoding::kHundreds), (Bytes{12, 34, 0, 7, 255, 99}));
  EXPECT_EQ(decodeValues({12, 34, 0, 7}, Encoding::kHundreds), (std::vector<int32_t>{1234, 7}));
  EXPECT_THROW(encodeValues({25600}, Encoding::kHundreds), ProtocolError);
  EXPECT_THROW(encodeValues({-1}, Encoding::kHundreds), ProtocolError);
  EXPECT_THROW(decodeValues({1, 100}, Encoding::kHundreds), ProtocolError);
}

TEST(ValueCodec, BigEndianSixteenBit)
{
  EXPECT_EQ(encodeValues({0x1234, 65535}, Encoding::kBigEndian16), (Bytes{0x12, 0x34, 0xFF, 0xFF}));
  EXPECT_EQ(decodeValues({0x12, 0x34}, Encoding::kBigEndian16), std::vector<int32_t>{0x1234});
  EXPECT_EQ(encodeValues({-2, 32767}, Encoding::kBigEndian16s), (Bytes{0xFF, 0xFE, 0x7F, 0xFF}));
  EXPECT_EQ(decodeValues({0xFF, 0xFE, 0x80, 0x00}, Encoding::kBigEndian16s), (std::vector<int32_t>{-2, -32768}));
  EXPECT_THROW(encodeValues({65536}, Encoding::kBigEndian16), ProtocolError);
  EXPECT_THROW(encodeValues({-32769}, Encoding::kBigEndian16s), ProtocolError);
  EXPECT_THROW(decodeValues({1, 2, 3}, Encoding::kBigEndian16), ProtocolError);  // odd length
}

TEST(ValueCodec, BytesAndNames)
{
  EXPECT_EQ(encodeValues({0, 255}, Encoding::kBytes), (Bytes{0, 255}));
  EXPECT_THROW(encodeValues({256}, Encoding::kBytes), ProtocolError);
  for (const char* name : {"bytes", "hundreds", "be16", "be16s"})
  {
    EXPECT_STREQ(toString(parseEncoding(name)), name);
  }
  EXPECT_THROW(parseEncoding("le16"), ConfigError);
  EXPECT_EQ(parseFraming("framed"), Framing::kFramed);
  EXPECT_THROW(parseFraming("crc"), ConfigError);
}
