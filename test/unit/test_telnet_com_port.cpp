// Telnet framing and COM-PORT-OPTION (RFC 854/855/2217) without a network: the decoder on every
// cut of a stream, the option negotiation's replies, the encoding of line settings.
#include <gtest/gtest.h>

#include "cnc_bridge/transport/telnet_com_port.h"

namespace cnc_bridge
{
namespace rfc2217
{
namespace
{
using Bytes = std::vector<uint8_t>;

struct Decoded
{
  Bytes data;
  std::vector<Event> events;
};

/// Feeds \p stream to a fresh decoder cut at \p cut (and whole when cut is 0 or the end).
Decoded decode(const Bytes& stream, size_t cut)
{
  Decoder decoder;
  Decoded out;
  decoder.feed(stream.data(), cut, out.data, out.events);
  decoder.feed(stream.data() + cut, stream.size() - cut, out.data, out.events);
  return out;
}

TEST(TelnetDecoder, DataAndEveryKindOfCommandSurviveEveryCut)
{
  // 'A', an escaped 0xFF, WILL ECHO, 'B', the answer to a baud rate of 0x0001C2FF (escaped in the
  // subnegotiation), NOP, 'C'.
  const Bytes stream = {'A',  kIac, kIac, kIac, kWill, kOptionEcho, 'B',  kIac, kSb, kOptionComPort, 101, 0x00,
                        0x01, 0xC2, kIac, kIac, kIac,  kSe,         kIac, 241,  'C'};
  for (size_t cut = 0; cut <= stream.size(); ++cut)
  {
    SCOPED_TRACE("cut at " + std::to_string(cut));
    const Decoded out = decode(stream, cut);
    EXPECT_EQ(out.data, (Bytes{'A', 0xFF, 'B', 'C'}));
    ASSERT_EQ(out.events.size(), 3u);
    EXPECT_EQ(out.events[0].kind, Event::Kind::kWill);
    EXPECT_EQ(out.events[0].option, kOptionEcho);
    EXPECT_EQ(out.events[1].kind, Event::Kind::kComPort);
    EXPECT_EQ(out.events[1].command, 101);
    EXPECT_EQ(out.events[1].value, (Bytes{0x00, 0x01, 0xC2, 0xFF}));
    EXPECT_EQ(out.events[2].kind, Event::Kind::kOther);
  }
}

TEST(TelnetDecoder, ACommandInsideASubnegotiationEndsItAndDataFollows)
{
  // IAC SB 44 105 1 IAC NOP: a broken subnegotiation must not swallow the data after it.
  const Decoded out = decode({kIac, kSb, kOptionComPort, 105, 1, kIac, 241, 'x', 'y'}, 0);
  EXPECT_EQ(out.data, (Bytes{'x', 'y'}));
  ASSERT_EQ(out.events.size(), 1u);
  EXPECT_EQ(out.events[0].kind, Event::Kind::kComPort);
  EXPECT_EQ(out.events[0].value, (Bytes{1}));
}

TEST(TelnetDecoder, AnotherOptionsSubnegotiationIsNotAComPortEvent)
{
  const Decoded out = decode({kIac, kSb, 24, 1, kIac, kSe, 'z'}, 3);  // terminal type
  EXPECT_EQ(out.data, (Bytes{'z'}));
  ASSERT_EQ(out.events.size(), 1u);
  EXPECT_EQ(out.events[0].kind, Event::Kind::kOther);
}

Event negotiation(Event::Kind kind, uint8_t option)
{
  Event event;
  event.kind = kind;
  event.option = option;
  return event;
}

TEST(TelnetOptions, StartAsksForComPortBinaryAndSuppressGoAhead)
{
  Options options;
  EXPECT_EQ(options.start(),
            (Bytes{kIac, kWill, kOptionComPort, kIac, kWill, kOptionBinary, kIac, kWill, kOptionSuppressGoAhead, kIac,
                   kDo, kOptionBinary, kIac, kDo, kOptionSuppressGoAhead}));
  EXPECT_FALSE(options.comPortAccepted());
}

TEST(TelnetOptions, AnswersToOurRequestsNeedNoReply)
{
  Options options;
  options.start();
  EXPECT_TRUE(options.reply(negotiation(Event::Kind::kDo, kOptionComPort)).empty());
  EXPECT_TRUE(options.comPortAccepted());
  EXPECT_TRUE(options.reply(negotiation(Event::Kind::kWill, kOptionBinary)).empty());
  // Said again (some servers repeat themselves): still nothing, so no loop.
  EXPECT_TRUE(options.reply(negotiation(Event::Kind::kDo, kOptionComPort)).empty());
  EXPECT_FALSE(options.binaryRefused());
}

TEST(TelnetOptions, TheServersOwnOffersAreAcceptedOrRefusedOnce)
{
  Options options;
  options.start();
  EXPECT_EQ(options.reply(negotiation(Event::Kind::kWill, kOptionEcho)), (Bytes{kIac, kDo, kOptionEcho}));
  EXPECT_TRUE(options.reply(negotiation(Event::Kind::kWill, kOptionEcho)).empty());
  const uint8_t kTerminalType = 24, kLineMode = 34;
  EXPECT_EQ(options.reply(negotiation(Event::Kind::kDo, kTerminalType)), (Bytes{kIac, kWont, kTerminalType}));
  EXPECT_EQ(options.reply(negotiation(Event::Kind::kWill, kLineMode)), (Bytes{kIac, kDont, kLineMode}));
  // Being told not to do what we do not do needs no answer.
  EXPECT_TRUE(options.reply(negotiation(Event::Kind::kDont, kTerminalType)).empty());
}

TEST(TelnetOptions, ARefusedComPortOrBinaryIsReported)
{
  Options options;
  options.start();
  EXPECT_TRUE(options.reply(negotiation(Event::Kind::kDont, kOptionComPort)).empty());  // our request refused
  EXPECT_TRUE(options.comPortRefused());
  EXPECT_FALSE(options.comPortAccepted());
  options.reply(negotiation(Event::Kind::kWont, kOptionBinary));
  EXPECT_TRUE(options.binaryRefused());
}

TEST(TelnetOptions, AnAgreedOptionWithdrawnIsAcknowledged)
{
  Options options;
  options.start();
  options.reply(negotiation(Event::Kind::kWill, kOptionSuppressGoAhead));
  EXPECT_EQ(options.reply(negotiation(Event::Kind::kWont, kOptionSuppressGoAhead)),
            (Bytes{kIac, kDont, kOptionSuppressGoAhead}));
  EXPECT_TRUE(options.reply(negotiation(Event::Kind::kWont, kOptionSuppressGoAhead)).empty());
}

TEST(ComPortSettings, LineSettingsAreEncodedAsRfc2217Says)
{
  SerialSettings settings;
  settings.baud = 115200;
  settings.data_bits = 7;
  settings.parity = Parity::kEven;
  settings.stop_bits = 2;
  settings.flow_control = FlowControl::kRtsCts;
  const auto requests = lineSettings(settings);
  ASSERT_EQ(requests.size(), 5u);
  EXPECT_EQ(requests[0].command, Command::kSetBaudRate);
  EXPECT_EQ(requests[0].value, (Bytes{0x00, 0x01, 0xC2, 0x00}));
  EXPECT_EQ(requests[1].value, (Bytes{7}));
  EXPECT_EQ(requests[2].value, (Bytes{3}));  // even
  EXPECT_EQ(requests[3].value, (Bytes{2}));
  EXPECT_EQ(requests[4].value, (Bytes{kControlHardware}));
  EXPECT_EQ(describeValue(Command::kSetBaudRate, requests[0].value), "115200");
  EXPECT_EQ(describeValue(Command::kSetParity, {2}), "odd");
  EXPECT_EQ(describeValue(Command::kSetControl, {kControlXonXoff}), "xon/xoff");
  EXPECT_EQ(flowControlSetting(FlowControl::kNone).value, (Bytes{kControlNoFlow}));
}

TEST(ComPortSettings, SubnegotiationAndDataEscape0xFF)
{
  EXPECT_EQ(subnegotiation(Command::kSetBaudRate, {0x00, 0x00, 0x00, 0xFF}),
            (Bytes{kIac, kSb, kOptionComPort, 1, 0, 0, 0, kIac, kIac, kIac, kSe}));
  Bytes out;
  const Bytes data = {0x01, 0xFF, 0xFF, 0x02};
  appendEscaped(data.data(), data.size(), out);
  EXPECT_EQ(out, (Bytes{0x01, 0xFF, 0xFF, 0xFF, 0xFF, 0x02}));
  // What is escaped decodes back to itself.
  const Decoded back = decode(out, 2);
  EXPECT_EQ(back.data, data);
  EXPECT_TRUE(back.events.empty());
}
}  // namespace
}  // namespace rfc2217
}  // namespace cnc_bridge
