// The PC-side session and the simulated master together: the master's behaviour driven through a
// scripted transport (deterministic, no threads), then a BusSession talking to a SimMaster over a
// real pty in both framings, with corrupted uplink bytes, unknown slaves and a silent master.
#include <gtest/gtest.h>

#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/slave_bus/bus_session.h"
#include "cnc_bridge/transport/serial_port.h"
#include "sim/slave_bus/sim_master.h"
#include "testing/fake_transport.h"
#include "testing/pty.h"

using namespace cnc_bridge;
using namespace cnc_bridge::slave_bus;
using Bytes = std::vector<uint8_t>;

namespace
{
std::vector<SimSlave> eightSlaves()
{
  std::vector<SimSlave> slaves;
  slaves.emplace_back(1, SimRole::kAxis, Encoding::kBigEndian16s);
  slaves.emplace_back(2, SimRole::kAxis, Encoding::kBigEndian16s);
  slaves.emplace_back(3, SimRole::kAxis, Encoding::kHundreds);
  slaves.emplace_back(4, SimRole::kTool, Encoding::kBytes);
  for (uint8_t a = 5; a <= 8; ++a)
  {
    slaves.emplace_back(a, SimRole::kGeneric, Encoding::kBytes);
  }
  return slaves;
}

std::vector<UplinkRecord> parseAll(const Bytes& bytes, Framing framing)
{
  UplinkParser parser(framing, 8);
  return parser.feed(bytes.data(), bytes.size());
}

/// A SimMaster serving a pty in its own thread; the test opens the slave side as a serial port.
class PtyBus
{
 public:
  PtyBus(Framing framing, unsigned corrupt_every = 0) : PtyBus(optionsFor(framing, corrupt_every)) {}
  explicit PtyBus(const SimMaster::Options& options)
  {
    master_ = std::make_unique<SimMaster>(pty_, eightSlaves(), options);
    thread_ = std::thread([this] { master_->run(stop_); });
    SerialSettings settings;
    settings.device = pty_.slavePath();
    settings.baud = 115200;
    port_ = std::make_unique<SerialPort>(settings);
  }
  ~PtyBus() { stopMaster(); }
  /// Stops the master thread; its slaves may be inspected afterwards.
  const SimMaster& stopMaster()
  {
    if (thread_.joinable())
    {
      stop_.stop();
      pty_.interrupt();
      thread_.join();
    }
    return *master_;
  }
  SerialPort& port() { return *port_; }

 private:
  static SimMaster::Options optionsFor(Framing framing, unsigned corrupt_every)
  {
    SimMaster::Options options;
    options.framing = framing;
    options.corrupt_uplink_every = corrupt_every;
    return options;
  }

  PtyMaster pty_;
  StopSignal stop_;
  std::unique_ptr<SimMaster> master_;
  std::thread thread_;
  std::unique_ptr<SerialPort> port_;
};

const Milliseconds kReplyTimeout(2000);  // generous: a loaded CI box; a healthy step takes < 1 ms
}  // namespace

TEST(SimMaster, PaperFrameMovesAxesTogglesToolAndEchoes)
{
  FakeTransport link;
  SimMaster master(link, eightSlaves(), {});
  // Slave 1 to 1000 (be16s), slave 2 to -5, slave 3 to 1234 (hundreds: [12, 34]), tool on, slave 6 data.
  const Bytes frame = encodeStep({{0x03, 0xE8}, {0xFF, 0xFB}, {12, 34}, {1}, {}, {99}, {}, {}});
  master.processInput(frame.data(), frame.size());
  EXPECT_TRUE(link.written().empty());  // slaves answer only when polled
  master.pollSlaves();
  const auto records = parseAll(link.written(), Framing::kRaw);
  ASSERT_EQ(records.size(), 5u);
  EXPECT_EQ(records[0].address, 1);
  EXPECT_EQ(records[0].payload, (Bytes{0x03, 0xE8}));
  EXPECT_EQ(records[1].payload, (Bytes{0xFF, 0xFB}));
  EXPECT_EQ(records[2].payload, (Bytes{12, 34}));
  EXPECT_EQ(records[3].address, 4);
  EXPECT_EQ(records[3].payload, Bytes{1});
  EXPECT_EQ(records[4].address, 6);
  EXPECT_EQ(records[4].payload, Bytes{99});
  EXPECT_EQ(master.slaves()[0].position(), 1000);
  EXPECT_EQ(master.slaves()[1].position(), -5);
  EXPECT_EQ(master.slaves()[2].position(), 1234);
  EXPECT_TRUE(master.slaves()[3].toolOn());
  // A slave answers once per payload: a second poll says nothing.
  link.clearWritten();
  master.pollSlaves();
  EXPECT_TRUE(link.written().empty());
  // Tool off.
  const Bytes off = encodeStep({{}, {}, {}, {0}});
  master.processInput(off.data(), off.size());
  master.pollSlaves();
  EXPECT_FALSE(master.slaves()[3].toolOn());
}

TEST(SimMaster, FramedModeReportsBadFramesAndUnknownSlaves)
{
  FakeTransport link;
  SimMaster::Options options;
  options.framing = Framing::kFramed;
  SimMaster master(link, eightSlaves(), options);
  auto corrupted = encodeStepForLink({{0x00, 0x10}}, Framing::kFramed);
  corrupted[4] ^= 0x01;
  master.processInput(corrupted.data(), corrupted.size());
  auto records = parseAll(link.written(), Framing::kFramed);
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(records[0].address, 0);
  EXPECT_EQ(records[0].payload, Bytes{static_cast<uint8_t>(MasterStatus::kBadFrame)});
  EXPECT_EQ(master.slaves()[0].position(), 0);  // the corrupted step did not move anything

  link.clearWritten();
  // Garbage, then a good frame for 9 slaves on an 8-slave bus.
  Bytes stream = {0x11, 0x22, 0x04};
  StepPayloads payloads(9);
  payloads[0] = {0x00, 0x10};
  payloads[8] = {7};
  const auto good = encodeStepForLink(payloads, Framing::kFramed);
  stream.insert(stream.end(), good.begin(), good.end());
  master.processInput(stream.data(), stream.size());
  master.pollSlaves();
  records = parseAll(link.written(), Framing::kFramed);
  ASSERT_EQ(records.size(), 2u);
  EXPECT_EQ(records[0].address, 0);
  EXPECT_EQ(records[0].payload, (Bytes{static_cast<uint8_t>(MasterStatus::kNoSuchSlave), 9}));
  EXPECT_EQ(records[1].address, 1);
  EXPECT_EQ(master.slaves()[0].position(), 16);
  EXPECT_EQ(master.stats().unknown_slaves, 1u);
}

TEST(SimMaster, LongEchoIsCutToWhatTheMasterReads)
{
  for (const Framing framing : {Framing::kRaw, Framing::kFramed})
  {
    FakeTransport link;
    SimMaster::Options options;
    options.framing = framing;
    SimMaster master(link, eightSlaves(), options);
    StepPayloads payloads(5);
    payloads[4] = Bytes(framing == Framing::kRaw ? kMaxPayload : 200, 0x33);
    const auto frame = encodeStepForLink(payloads, framing);
    master.processInput(frame.data(), frame.size());
    master.pollSlaves();
    const auto records = parseAll(link.written(), framing);
    ASSERT_EQ(records.size(), 1u);
    EXPECT_EQ(records[0].payload, Bytes(kMaxReply, 0x33));
  }
}

TEST(SimMaster, PayloadLongerThanAnI2cFrameIsReportedNotDelivered)
{
  // Found by fuzzing: a raw length byte of 252..255 is valid on the serial link but does not fit
  // in one WirePacker frame.
  FakeTransport link;
  SimMaster master(link, eightSlaves(), {});
  Bytes frame = {5, 0, 0, 0, 0, 255};
  frame.insert(frame.end(), 255, 0x44);
  master.processInput(frame.data(), frame.size());
  const auto records = parseAll(link.written(), Framing::kRaw);
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(records[0].address, 0);
  EXPECT_EQ(records[0].payload, (Bytes{static_cast<uint8_t>(MasterStatus::kPayloadTooLong), 5}));
  EXPECT_EQ(master.stats().oversize_payloads, 1u);
  EXPECT_EQ(master.stats().deliveries, 0u);
}

TEST(SimMaster, PayloadOverTheConfiguredFrameSizeIsReportedForItsSlave)
{
  // A master whose I2C frames carry 8 bytes: a 9-byte payload for slave 6 is reported with status 4
  // and that slave's address, and not delivered; slave 5's payload in the same frame still is.
  FakeTransport link;
  SimMaster::Options options;
  options.wire = WireFormat::of(WireCrc::kSpec, 8);
  SimMaster master(link, eightSlaves(), options);
  const Bytes frame = encodeStep({{}, {}, {}, {}, Bytes(8, 5), Bytes(9, 6)});
  master.processInput(frame.data(), frame.size());
  master.pollSlaves();
  const auto records = parseAll(link.written(), Framing::kRaw);
  ASSERT_EQ(records.size(), 2u);
  EXPECT_EQ(records[0].address, 0);
  EXPECT_EQ(records[0].payload, (Bytes{static_cast<uint8_t>(MasterStatus::kPayloadTooLong), 6}));
  EXPECT_EQ(records[1].address, 5);
  EXPECT_EQ(master.stats().oversize_payloads, 1u);
  EXPECT_EQ(master.stats().deliveries, 1u);
  // Framed, the uplink needs frames for an address and a 32-byte answer.
  options.framing = Framing::kFramed;
  EXPECT_THROW(SimMaster(link, eightSlaves(), options), ConfigError);
  options.wire = WireFormat::of(WireCrc::kSpec, 1 + kMaxReply);
  EXPECT_NO_THROW(SimMaster(link, eightSlaves(), options));
}

TEST(SimMaster, NoisySlaveAnswerIsReportedWithStatus3AndItsAddress)
{
  FakeTransport link;
  auto slaves = eightSlaves();
  slaves[6].setNoisy(true);  // address 7
  SimMaster master(link, std::move(slaves), {});
  const Bytes frame = encodeStep({{}, {}, {}, {}, {}, {1}, {2}});
  master.processInput(frame.data(), frame.size());
  master.pollSlaves();
  const auto records = parseAll(link.written(), Framing::kRaw);
  ASSERT_EQ(records.size(), 2u);
  EXPECT_EQ(records[0].address, 6);
  EXPECT_EQ(records[1].address, 0);
  EXPECT_EQ(records[1].payload, (Bytes{static_cast<uint8_t>(MasterStatus::kSlaveNoAnswer), 7}));
  EXPECT_EQ(master.stats().slave_errors, 1u);
}

TEST(SimMaster, LibraryCrcOnTheI2cBusAndTheFramedLink)
{
  FakeTransport link;
  SimMaster::Options options;
  options.framing = Framing::kFramed;
  options.wire = WireFormat::of(WireCrc::kLibrary);
  SimMaster master(link, eightSlaves(), options);
  const auto step = encodeStepForLink({{}, {}, {}, {}, {0x31, 0x32, 0x33}}, Framing::kFramed, options.wire);
  master.processInput(step.data(), step.size());
  master.pollSlaves();
  // The echo of slave 5 as the library frames it: [5, 31, 32, 33], CRC over the data only.
  const Bytes record = {5, 0x31, 0x32, 0x33};
  EXPECT_EQ(link.written(), WirePacker::pack(record, options.wire));
  EXPECT_EQ(link.written()[6], crc8Maxim(record.data(), record.size()));
  EXPECT_EQ(master.slaves()[4].rejected(), 0u);  // the slave checked the I2C frame with the same CRC
  // A step framed with the spec's CRC fails the library master's check.
  link.clearWritten();
  const auto spec_step = encodeStepForLink({{}, {}, {}, {}, {1}}, Framing::kFramed);
  master.processInput(spec_step.data(), spec_step.size());
  const auto records =
      UplinkParser(Framing::kFramed, 8, options.wire).feed(link.written().data(), link.written().size());
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(records[0].payload, Bytes{static_cast<uint8_t>(MasterStatus::kBadFrame)});
}

TEST(SimMaster, FramedModeResynchronisesAfterASilenceWithNoGapConfigured)
{
  // A stray start byte with a large length (spec frames may be 255 bytes long) swallows the step
  // behind it until the line goes quiet; then the master abandons it and runs the step.
  FakeTransport link;
  SimMaster::Options options;
  options.framing = Framing::kFramed;
  ASSERT_EQ(options.resync_gap.count(), 0);
  SimMaster master(link, eightSlaves(), options);
  Bytes stream = {0x02, 0xF0, 0x11};
  const auto step = encodeStepForLink({{0x01, 0x00}}, Framing::kFramed);
  stream.insert(stream.end(), step.begin(), step.end());
  master.processInput(stream.data(), stream.size());
  EXPECT_EQ(master.slaves()[0].position(), 0);
  master.onSilence();
  EXPECT_EQ(master.slaves()[0].position(), 256);
  EXPECT_EQ(master.stats().resyncs, 1u);
  master.pollSlaves();
  const auto records = parseAll(link.written(), Framing::kFramed);
  ASSERT_FALSE(records.empty());
  EXPECT_EQ(records.back().address, 1);
}

TEST(SimMaster, SlaveIgnoresAPayloadItCannotDecode)
{
  FakeTransport link;
  SimMaster master(link, eightSlaves(), {});
  const Bytes frame = encodeStep({{1, 2, 3}});  // three bytes are not a whole be16s value
  master.processInput(frame.data(), frame.size());
  master.pollSlaves();
  EXPECT_TRUE(link.written().empty());
  EXPECT_EQ(master.slaves()[0].rejected(), 1u);
}

TEST(BusSession, PadsToTheBusSizeAndRefusesMore)
{
  FakeTransport link;
  BusSession session(link, Framing::kRaw, 8);
  session.send({{10}, {20}, {30}, {}, {}, {99}});
  EXPECT_EQ(link.written(), (Bytes{8, 1, 10, 1, 20, 1, 30, 0, 0, 1, 99, 0, 0}));
  EXPECT_THROW(session.send(StepPayloads(9)), ProtocolError);
  EXPECT_THROW(BusSession(link, Framing::kRaw, 0), ProtocolError);
  EXPECT_EQ(session.stats().steps_sent, 1u);
}

TEST(BusSession, RefusesAPayloadOverTheMastersFrameSize)
{
  FakeTransport link;
  BusSession session(link, Framing::kRaw, 8, Milliseconds(50), WireFormat::of(WireCrc::kLibrary));
  EXPECT_THROW(session.send({{}, {}, Bytes(125, 1)}), ProtocolError);
  EXPECT_TRUE(link.written().empty());
  session.send({{}, {}, Bytes(124, 1)});
  EXPECT_EQ(link.written().size(), 1u + 8u + 124u);
}

TEST(BusSession, SilentMasterTimesOutEverySlaveThatGotAPayload)
{
  FakeTransport link;
  BusSession session(link, Framing::kRaw, 4);
  const auto result = session.step({{1}, {}, {3}}, Milliseconds(30));
  EXPECT_TRUE(result.replies.empty());
  EXPECT_EQ(result.missing, (Bytes{1, 3}));
}

TEST(BusSession, TornRecordIsDroppedAfterASilence)
{
  FakeTransport link;
  BusSession session(link, Framing::kRaw, 4, Milliseconds(10));
  link.feed(Bytes{2, 5, 1});  // a reply of 5 bytes, cut after one
  EXPECT_TRUE(session.poll(Milliseconds(50)).empty());
  EXPECT_TRUE(session.poll(Milliseconds(50)).empty());  // the silence: dropped
  EXPECT_EQ(session.stats().resyncs, 1u);
  link.feed(Bytes{3, 1, 7});
  const auto records = session.poll(Milliseconds(50));
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(records[0].address, 3);
}

class PtyRoundTrip : public ::testing::TestWithParam<Framing>
{
};

TEST_P(PtyRoundTrip, EightSlaveStepsMoveTheAxesAndEverySlaveAnswers)
{
  PtyBus bus(GetParam());
  BusSession session(bus.port(), GetParam(), 8);
  for (int i = 1; i <= 20; ++i)
  {
    StepPayloads payloads = {encodeValues({i * 10}, Encoding::kBigEndian16s),
                             encodeValues({-i}, Encoding::kBigEndian16s),
                             encodeValues({i * 100 + 5}, Encoding::kHundreds),
                             {static_cast<uint8_t>(i % 2)},
                             {5},
                             {6, 6},
                             {},
                             {8, 8, 8, 8}};
    const auto result = session.step(payloads, kReplyTimeout);
    ASSERT_TRUE(result.missing.empty()) << "step " << i;
    ASSERT_EQ(result.replies.size(), 7u);
    EXPECT_EQ(decodeValues(result.replies[0].payload, Encoding::kBigEndian16s), std::vector<int32_t>{i * 10});
    EXPECT_EQ(decodeValues(result.replies[1].payload, Encoding::kBigEndian16s), std::vector<int32_t>{-i});
    EXPECT_EQ(decodeValues(result.replies[2].payload, Encoding::kHundreds), std::vector<int32_t>{i * 100 + 5});
    EXPECT_EQ(result.replies[3].payload, Bytes{static_cast<uint8_t>(i % 2)});
    EXPECT_EQ(result.replies[6].address, 8);
    EXPECT_EQ(result.replies[6].payload, (Bytes{8, 8, 8, 8}));
  }
  const auto& master = bus.stopMaster();
  EXPECT_EQ(master.stats().frames, 20u);
  EXPECT_EQ(master.slaves()[0].position(), 200);
  EXPECT_EQ(master.slaves()[1].position(), -20);
  EXPECT_FALSE(master.slaves()[3].toolOn());
  EXPECT_EQ(session.stats().replies, 140u);
}

INSTANTIATE_TEST_SUITE_P(BothFramings, PtyRoundTrip, ::testing::Values(Framing::kRaw, Framing::kFramed));

TEST(PtyFramed, CorruptedUplinkIsCountedAndLaterStepsStillWork)
{
  // Every second uplink write has one byte changed: the PC's CRC check catches it.
  PtyBus bus(Framing::kFramed, 2);
  BusSession session(bus.port(), Framing::kFramed, 8);
  int complete = 0;
  for (int i = 0; i < 10; ++i)
  {
    // One slave per step so each step is one uplink write; a corrupted one leaves that slave missing.
    const auto result = session.step({{static_cast<uint8_t>(i), 0}}, Milliseconds(1000));
    complete += result.missing.empty() ? 1 : 0;
  }
  EXPECT_EQ(complete, 5);
  EXPECT_EQ(session.stats().link.crc_errors + session.stats().link.framing_errors, 5u);
}

TEST(PtyFramed, UnknownSlavesAreReportedNotWaitedFor)
{
  PtyBus bus(Framing::kFramed);
  BusSession session(bus.port(), Framing::kFramed, 10);
  StepPayloads payloads(10);
  payloads[4] = {1};
  payloads[9] = {2};
  const auto start = std::chrono::steady_clock::now();
  const auto result = session.step(payloads, Milliseconds(5000));
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::milliseconds(4000));  // no timeout wait
  EXPECT_EQ(result.missing, Bytes{10});
  ASSERT_EQ(result.master_status.size(), 1u);
  EXPECT_EQ(result.master_status[0].payload, (Bytes{static_cast<uint8_t>(MasterStatus::kNoSuchSlave), 10}));
  ASSERT_EQ(result.replies.size(), 1u);
  EXPECT_EQ(result.replies[0].address, 5);
}

TEST(PtyFramed, GarbageFromThePcBetweenStepsDoesNotLoseTheNextStep)
{
  PtyBus bus(Framing::kFramed);
  BusSession session(bus.port(), Framing::kFramed, 8);
  bus.port().write(Bytes{0x55, 0x04, 0xAA, 0x00});  // line noise with no start byte
  const auto result = session.step({{0x01, 0x00}}, kReplyTimeout);
  EXPECT_TRUE(result.missing.empty());
  EXPECT_EQ(bus.stopMaster().slaves()[0].position(), 256);
}

TEST(PtyFramed, StrayStartByteWithALargeLengthDoesNotStallTheNextStep)
{
  // No resync gap is configured (the simulator's default): framed mode resynchronises anyway.
  PtyBus bus(Framing::kFramed);
  BusSession session(bus.port(), Framing::kFramed, 8);
  bus.port().write(Bytes{0x33, 0x02, 0xF0, 0x11});  // garbage with a start byte and length 240
  const auto result = session.step({{0x01, 0x00}}, kReplyTimeout);
  EXPECT_TRUE(result.missing.empty());
  ASSERT_EQ(result.replies.size(), 1u);
  EXPECT_EQ(result.replies[0].payload, (Bytes{0x01, 0x00}));
  EXPECT_EQ(bus.stopMaster().slaves()[0].position(), 256);
}

TEST(PtyFramed, LibraryCrcStepsRoundTrip)
{
  SimMaster::Options options;
  options.framing = Framing::kFramed;
  options.wire = WireFormat::of(WireCrc::kLibrary);
  PtyBus bus(options);
  BusSession session(bus.port(), Framing::kFramed, 8, Milliseconds(50), options.wire);
  for (int i = 1; i <= 5; ++i)
  {
    const auto result = session.step({encodeValues({i}, Encoding::kBigEndian16s), {}, {}, {}, {9, 9}}, kReplyTimeout);
    ASSERT_TRUE(result.missing.empty()) << "step " << i;
    ASSERT_EQ(result.replies.size(), 2u);
  }
  EXPECT_EQ(session.stats().link.crc_errors, 0u);
  EXPECT_EQ(bus.stopMaster().slaves()[0].position(), 5);
}
