// Haas MDC reply parsing, matching and state mapping. The reply lines are written in the formats
// the Haas "Machine Data Collection" documentation shows (SERIAL NUMBER, 1234567; MODE, (MEM);
// PROGRAM, O00110, IDLE, PARTS, 4523; STATUS, BUSY; MACRO, value and MACRO, n, value; ?, ?Q105),
// with the variants a tolerant host must accept: the '>' prompt on either side, Classic STX/ETB
// framing, an echoed query, extra spaces, lower case and 7-bit lines read with the parity bit set.
// Replies of real controls, byte by byte: test_mdc_fixtures.cpp.
#include <gtest/gtest.h>

#include <cmath>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mdc/mdc_protocol.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mdc;

namespace
{
Reply parsed(const std::string& line)
{
  auto reply = parseReply(line);
  EXPECT_TRUE(reply) << line;
  return reply.value_or(Reply());
}
}  // namespace

TEST(MdcQuery, TextIsWhatTheControlExpects)
{
  EXPECT_EQ(q(100).text(), "?Q100");
  EXPECT_EQ(q(500).text(), "?Q500");
  EXPECT_EQ(macroQuery(5021).text(), "?Q600 5021");
  Query write;
  write.letter = 'E';
  write.code = 100;
  write.argument = -7.5;
  EXPECT_EQ(write.text(), "?E100 -7.5");
  write.argument = 3;
  EXPECT_EQ(write.text(), "?E100 3");
}

// Exact or refused: a value the write cannot carry exactly is refused with the reason, never cut
// to the wire's digits (1e300), rounded to its decimals (1e-7 to 0) or sent as NaN.
TEST(MdcQuery, AWriteTheWireCannotCarryExactlyIsRefused)
{
  EXPECT_EQ(writeQuery(100, 42.5).text(), "?E100 42.5");
  EXPECT_EQ(writeQuery(100, -1).text(), "?E100 -1");
  EXPECT_EQ(writeQuery(100, 0.000001).text(), "?E100 0.000001");
  EXPECT_EQ(writeQuery(100, 2147483648.0).text(), "?E100 2147483648");  // INT_MAX + 1: a macro value
  EXPECT_EQ(writeQuery(100, 999999999999999.0).text(), "?E100 999999999999999");
  EXPECT_EQ(writeQuery(100, 0.1).text(), "?E100 0.1");
  const auto reason = [](double value)
  {
    try
    {
      writeQuery(100, value);
    }
    catch (const ProtocolError& e)
    {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(reason(1e300),
            "value 1.0000000000000001e+300 cannot be written exactly: MDC numbers carry at most 15 "
            "digits before the point (magnitude below 1e15)");
  EXPECT_EQ(reason(1e-7),
            "value 9.9999999999999995e-08 cannot be written exactly: MDC numbers carry at most 6 "
            "decimals (it would arrive as 0.)");
  EXPECT_NE(reason(1.23456789).find("at most 6 decimals (it would arrive as 1.234568)"), std::string::npos);
  EXPECT_NE(reason(std::nan("")).find("cannot be written exactly: MDC numbers are finite"), std::string::npos);
  EXPECT_NE(reason(HUGE_VAL).find("MDC numbers are finite"), std::string::npos);
  EXPECT_NE(reason(-HUGE_VAL).find("MDC numbers are finite"), std::string::npos);
  EXPECT_NE(reason(1e15).find("magnitude below 1e15"), std::string::npos);
  EXPECT_NE(reason(-1e15).find("magnitude below 1e15"), std::string::npos);
}

TEST(MdcParser, RecognisesEveryDocumentedReply)
{
  const std::pair<const char*, ReplyKind> cases[] = {
      {">SERIAL NUMBER, 1234567", ReplyKind::kSerialNumber},
      {">SOFTWARE VERSION, 100.20.000.1200", ReplyKind::kSoftwareVersion},
      {">MODEL, VF2D", ReplyKind::kModel},
      {">MODE, (MEM)", ReplyKind::kMode},
      {">TOOL CHANGES, 23", ReplyKind::kToolChanges},
      {">USING TOOL, 1", ReplyKind::kToolInUse},
      {">P.O. TIME, 00027:50:59", ReplyKind::kPowerOnTime},
      {">C.S. TIME, 00003:02:57", ReplyKind::kMotionTime},
      {">LAST CYCLE, 000:00:25", ReplyKind::kLastCycle},
      {">PREV CYCLE, 000:00:24", ReplyKind::kPreviousCycle},
      {">M30 #1, 553", ReplyKind::kPartsCounter1},
      {">M30 #2, 12", ReplyKind::kPartsCounter2},
      {">PROGRAM, O00110, IDLE, PARTS, 4523", ReplyKind::kProgramStatus},
      {">STATUS, BUSY", ReplyKind::kProgramStatus},
      {">MACRO, 5021, -1.234500", ReplyKind::kMacro},
      {">?, ?Q105", ReplyKind::kUnknownQuery},
      {">!", ReplyKind::kWriteAck},
      {">SOMETHING NEW, 1", ReplyKind::kOther},
  };
  for (const auto& [line, kind] : cases)
  {
    EXPECT_EQ(parsed(line).kind, kind) << line;
  }
}

TEST(MdcParser, ToleratesFramingEchoesSpacesAndCase)
{
  const char* variants[] = {
      ">PROGRAM, O00110, IDLE, PARTS, 4523\r\n",
      "PROGRAM, O00110, IDLE, PARTS, 4523",
      "PROGRAM,O00110,IDLE,PARTS,4523",
      ">  PROGRAM ,  O00110 ,IDLE,  PARTS ,   4523  ",
      "\x02PROGRAM, O00110, IDLE, PARTS, 4523\x17\r\n>",
      ">>PROGRAM, O00110, IDLE, PARTS, 4523",
      "?Q500 PROGRAM, O00110, IDLE, PARTS, 4523",
      ">?Q500PROGRAM, O00110, IDLE, PARTS, 4523",
      "Q500 PROGRAM, O00110, IDLE, PARTS, 4523",
      "program, O00110, idle, parts, 4523",
      "PROGRAM,\tO00110, IDLE, PARTS, 4523",
  };
  for (const char* line : variants)
  {
    const Reply reply = parsed(line);
    ASSERT_EQ(reply.kind, ReplyKind::kProgramStatus) << line;
    const ProgramStatus status = toProgramStatus(reply);
    EXPECT_EQ(status.program, "O00110") << line;
    EXPECT_EQ(status.status, "IDLE") << line;
    ASSERT_TRUE(status.parts) << line;
    EXPECT_EQ(*status.parts, 4523) << line;
  }
}

TEST(MdcParser, SevenBitLineReadAsEightBitsStillParses)
{
  // 7E1 read as 8N1: characters with an odd number of ones carry the parity bit (bit 7).
  std::string line = "MODE, (MEM)";
  for (auto& c : line)
  {
    if (__builtin_popcount(static_cast<unsigned char>(c)) % 2)
      c = static_cast<char>(static_cast<unsigned char>(c) | 0x80);
  }
  const Reply reply = parsed(line);
  EXPECT_EQ(reply.kind, ReplyKind::kMode);
  EXPECT_EQ(valueOf(reply), "(MEM)");
}

TEST(MdcParser, EchoAloneOrPromptAloneIsNotAReply)
{
  EXPECT_FALSE(parseReply(">"));
  EXPECT_FALSE(parseReply(""));
  EXPECT_FALSE(parseReply("\r"));
  EXPECT_FALSE(parseReply("?Q500"));
  EXPECT_FALSE(parseReply(">?Q600 5021"));
  EXPECT_FALSE(parseReply("\x02\x17"));
}

TEST(MdcParser, EchoWithArgumentIsRemoved)
{
  const Reply reply = parsed("?Q600 5021 MACRO, 5021, 1.5");
  EXPECT_EQ(reply.echoed, "?Q600 5021");
  EXPECT_EQ(reply.kind, ReplyKind::kMacro);
  EXPECT_EQ(macroOf(reply).variable, 5021);
  EXPECT_EQ(macroOf(reply).value, 1.5);
}

TEST(MdcParser, BusyStatusHasNoProgramOrParts)
{
  const ProgramStatus status = toProgramStatus(parsed(">STATUS, BUSY"));
  EXPECT_EQ(status.status, "BUSY");
  EXPECT_TRUE(status.program.empty());
  EXPECT_FALSE(status.parts);
  EXPECT_EQ(mapExecution(status.status), Execution::kActive);
}

TEST(MdcParser, MalformedValuesAreProtocolErrors)
{
  EXPECT_THROW(toProgramStatus(parsed("PROGRAM, O00110")), ProtocolError);
  EXPECT_THROW(toProgramStatus(parsed("PROGRAM, O1, IDLE, PARTS, many")), ProtocolError);
  EXPECT_THROW(toProgramStatus(parsed("PROGRAM, O1, IDLE, PARTS, -3")), ProtocolError);
  EXPECT_THROW(toProgramStatus(parsed("STATUS")), ProtocolError);
  EXPECT_THROW(toProgramStatus(parsed("MODE, (MEM)")), ProtocolError);
  EXPECT_THROW(macroOf(parsed("MACRO")), ProtocolError);
  EXPECT_THROW(macroOf(parsed("MACRO, x")), ProtocolError);
  EXPECT_THROW(macroOf(parsed("MACRO, 1, 2, 3")), ProtocolError);
  EXPECT_THROW(macroOf(parsed("MACRO, x, 1")), ProtocolError);
  EXPECT_THROW(macroOf(parsed("MACRO, 1.5, 1")), ProtocolError);
  EXPECT_THROW(macroOf(parsed("MACRO, 100, nan")), ProtocolError);
  EXPECT_THROW(integerOf(parsed("USING TOOL, 1.5")), ProtocolError);
  EXPECT_THROW(valueOf(parsed("MODEL,")), ProtocolError);
  EXPECT_THROW(parseDuration("12"), ProtocolError);
  EXPECT_THROW(parseDuration("1:2:3:4"), ProtocolError);
  EXPECT_THROW(parseDuration("1:-2:3"), ProtocolError);
  EXPECT_THROW(parseDuration("a:b"), ProtocolError);
}

TEST(MdcParser, DurationsAreHoursMinutesSeconds)
{
  EXPECT_DOUBLE_EQ(parseDuration("00027:50:59"), 27 * 3600 + 50 * 60 + 59);
  EXPECT_DOUBLE_EQ(parseDuration("000:00:25"), 25);
  EXPECT_DOUBLE_EQ(parseDuration(" 1:30 "), 90);
}

TEST(MdcMatching, RepliesMatchTheirQueryByContent)
{
  EXPECT_TRUE(answers(q(500), parsed("STATUS, BUSY")));
  EXPECT_TRUE(answers(q(500), parsed("PROGRAM, O1, IDLE, PARTS, 1")));
  EXPECT_FALSE(answers(q(104), parsed("PROGRAM, O1, IDLE, PARTS, 1")));
  EXPECT_TRUE(answers(q(104), parsed("MODE, (MDI)")));
  EXPECT_FALSE(answers(q(102), parsed("MODE, (MDI)")));  // MODE is not MODEL
  EXPECT_TRUE(answers(q(102), parsed("MODEL, VF2")));
  EXPECT_TRUE(answers(macroQuery(5021), parsed("MACRO, 5021, 1.0")));
  EXPECT_TRUE(answers(macroQuery(5021), parsed("MACRO, 5021.000, 1.0")));
  EXPECT_FALSE(answers(macroQuery(5021), parsed("MACRO, 5022, 1.0")));
  EXPECT_FALSE(answers(q(600), parsed("MACRO, 5021, 1.0")));
  // NGC: "MACRO, value" names no variable, so it answers whichever Q600 is in flight.
  EXPECT_TRUE(answers(macroQuery(5021), parsed("MACRO, 1.0")));
  EXPECT_FALSE(answers(q(500), parsed("MACRO, 1.0")));
  // A Classic rejection names no query: it answers the one in flight.
  EXPECT_TRUE(answers(q(105), parsed("\x02UNKNOWN\x17")));
  EXPECT_TRUE(answers(macroQuery(99999), parsed("INVALID NUMBER")));
  EXPECT_TRUE(answers(q(105), parsed("?, ?Q105")));
  EXPECT_FALSE(answers(q(104), parsed("?, ?Q105")));
  EXPECT_TRUE(answers(macroQuery(99999), parsed("?, ?Q600 99999")));
  EXPECT_FALSE(answers(macroQuery(5021), parsed("?, ?Q600 99999")));
  EXPECT_TRUE(answers(macroQuery(5021), parsed("?, ?Q600")));
  EXPECT_FALSE(answers(q(500), parsed("?")));
  EXPECT_FALSE(answers(q(500), parsed("SOMETHING NEW, 1")));
}

TEST(MdcMapping, HaasStatesMapLikeMtconnectAgents)
{
  EXPECT_EQ(mapExecution("IDLE"), Execution::kReady);
  EXPECT_EQ(mapExecution("BUSY"), Execution::kActive);
  EXPECT_EQ(mapExecution("FEED HOLD"), Execution::kPaused);
  EXPECT_EQ(mapExecution("feed  hold"), Execution::kPaused);
  EXPECT_EQ(mapExecution("ALARM"), Execution::kAlarm);
  EXPECT_EQ(mapExecution("ALARM ON"), Execution::kAlarm);
  EXPECT_EQ(mapExecution("STOP"), Execution::kStopped);
  EXPECT_EQ(mapExecution("WHATEVER"), Execution::kUnknown);
  EXPECT_EQ(mapMode("(MEM)"), Mode::kAuto);
  EXPECT_EQ(mapMode("(MDI)"), Mode::kMdi);
  EXPECT_EQ(mapMode("(JOG)"), Mode::kManual);
  EXPECT_EQ(mapMode("(HAND JOG)"), Mode::kManual);
  EXPECT_EQ(mapMode("(ZERO RET)"), Mode::kHoming);
  EXPECT_EQ(mapMode("ZERO  RET"), Mode::kHoming);
  EXPECT_EQ(mapMode("(EDIT)"), Mode::kEdit);
  EXPECT_EQ(mapMode("(LIST PROG)"), Mode::kEdit);
  EXPECT_EQ(mapMode("(DNC)"), Mode::kDnc);
  EXPECT_EQ(mapMode("(SOMETHING)"), Mode::kUnknown);
}

TEST(MdcRawQuery, OnlyReadOnlyQueriesPass)
{
  ASSERT_TRUE(parseReadOnlyQuery("?Q500"));
  EXPECT_EQ(parseReadOnlyQuery("?Q500")->code, 500);
  EXPECT_EQ(parseReadOnlyQuery("Q104")->code, 104);
  EXPECT_EQ(parseReadOnlyQuery("?q600 5021")->argument, 5021.0);
  EXPECT_FALSE(parseReadOnlyQuery("?E100 5"));
  EXPECT_FALSE(parseReadOnlyQuery("?Q50"));
  EXPECT_FALSE(parseReadOnlyQuery("?Q5000"));
  EXPECT_FALSE(parseReadOnlyQuery("?Q500\r\n?E100 5"));
  EXPECT_FALSE(parseReadOnlyQuery("?Q600 1 2"));
  EXPECT_FALSE(parseReadOnlyQuery("?Q600 x"));
  EXPECT_FALSE(parseReadOnlyQuery(""));
  EXPECT_FALSE(parseReadOnlyQuery("hello"));
}
