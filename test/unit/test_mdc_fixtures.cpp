// Haas MDC replies from outside this project, fed byte for byte through MdcClient (line assembly,
// parsing, matching) and the decoders. The fixtures are test/data/mdc/*.mdcwire; README.md there
// names the source of every one. A fixture file is a sequence of exchanges on one connection:
//
//   query ?Q500                      the query the client sends
//   reply >STATUS, BUSY\r\n>         bytes the control sends in answer (\r \n \t \\ \xHH escapes)
//   reply-7e1 ...                    the same, as a 7E1 line read by an 8-bit port (parity in bit 7)
//   expect status=BUSY               one expectation about the reply taken as the answer
//
// Expectations: kind (ReplyKind name), value, integer, seconds, program, status, parts (or none),
// execution, mode, variable (or none), macro (a number), foreign (other replies seen meanwhile),
// and "unanswered" (no reply within the timeout).
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mdc/mdc_client.h"
#include "cnc_bridge/mdc/mdc_protocol.h"
#include "testing/fake_transport.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mdc;
using namespace std::chrono_literals;

namespace
{
struct Exchange
{
  size_t line = 0;
  std::string query;
  std::string reply;
  std::vector<std::pair<std::string, std::string>> expect;
};

std::string unescape(const std::string& text, size_t line)
{
  std::string out;
  for (size_t i = 0; i < text.size(); ++i)
  {
    if (text[i] != '\\' || i + 1 >= text.size())
    {
      out.push_back(text[i]);
      continue;
    }
    const char c = text[++i];
    if (c == 'r')
      out.push_back('\r');
    else if (c == 'n')
      out.push_back('\n');
    else if (c == 't')
      out.push_back('\t');
    else if (c == '\\')
      out.push_back('\\');
    else if (c == 'x' && i + 2 < text.size())
    {
      out.push_back(static_cast<char>(std::stoi(text.substr(i + 1, 2), nullptr, 16)));
      i += 2;
    }
    else
      throw std::runtime_error("line " + std::to_string(line) + ": unknown escape \\" + c);
  }
  return out;
}

// Even parity on 7 bits: bit 7 set where the low 7 bits have an odd number of ones.
std::string withEvenParity(std::string bytes)
{
  for (auto& c : bytes)
  {
    const auto byte = static_cast<unsigned char>(c) & 0x7F;
    c = static_cast<char>(__builtin_popcount(byte) % 2 ? byte | 0x80 : byte);
  }
  return bytes;
}

std::vector<Exchange> load(const std::string& path)
{
  std::ifstream in(path);
  if (!in)
    throw std::runtime_error("cannot open " + path);
  std::vector<Exchange> exchanges;
  std::string text;
  size_t number = 0;
  while (std::getline(in, text))
  {
    ++number;
    if (text.empty() || text[0] == '#')
      continue;
    const size_t space = text.find(' ');
    const std::string word = text.substr(0, space);
    const std::string rest = space == std::string::npos ? "" : text.substr(space + 1);
    if (word == "query")
    {
      exchanges.push_back(Exchange{number, rest, "", {}});
      continue;
    }
    if (exchanges.empty())
      throw std::runtime_error(path + ":" + std::to_string(number) + ": '" + word + "' before any query");
    Exchange& e = exchanges.back();
    if (word == "reply")
      e.reply += unescape(rest, number);
    else if (word == "reply-7e1")
      e.reply += withEvenParity(unescape(rest, number));
    else if (word == "expect")
    {
      const size_t eq = rest.find('=');
      e.expect.emplace_back(rest.substr(0, eq), eq == std::string::npos ? "" : rest.substr(eq + 1));
    }
    else
      throw std::runtime_error(path + ":" + std::to_string(number) + ": unknown word '" + word + "'");
  }
  return exchanges;
}

// Checks one expectation against the reply taken as the answer.
void check(const std::string& key, const std::string& want, const Reply& reply, uint64_t foreign)
{
  if (key == "kind")
    EXPECT_EQ(toString(reply.kind), want);
  else if (key == "value")
    EXPECT_EQ(valueOf(reply), want);
  else if (key == "integer")
    EXPECT_EQ(integerOf(reply), std::stoll(want));
  else if (key == "seconds")
    EXPECT_DOUBLE_EQ(parseDuration(valueOf(reply)), std::stod(want));
  else if (key == "program")
    EXPECT_EQ(toProgramStatus(reply).program, want);
  else if (key == "status")
    EXPECT_EQ(toProgramStatus(reply).status, want);
  else if (key == "parts")
  {
    const auto parts = toProgramStatus(reply).parts;
    if (want == "none")
      EXPECT_FALSE(parts);
    else
    {
      ASSERT_TRUE(parts);
      EXPECT_EQ(*parts, std::stoll(want));
    }
  }
  else if (key == "execution")
    EXPECT_STREQ(toString(mapExecution(toProgramStatus(reply).status)), want.c_str());
  else if (key == "mode")
    EXPECT_STREQ(toString(mapMode(valueOf(reply))), want.c_str());
  else if (key == "variable")
  {
    const auto variable = macroOf(reply).variable;
    if (want == "none")
      EXPECT_FALSE(variable);
    else
    {
      ASSERT_TRUE(variable);
      EXPECT_EQ(*variable, std::stoi(want));
    }
  }
  else if (key == "macro")
    EXPECT_DOUBLE_EQ(macroOf(reply).value, std::stod(want));
  else if (key == "foreign")
    EXPECT_EQ(foreign, std::stoull(want));
  else
    FAIL() << "unknown expectation " << key;
}

// Plays every exchange of \p file on one connection, the control's bytes arriving one at a time.
void play(const std::string& file)
{
  const auto exchanges = load(std::string(MDC_TEST_DATA) + "/" + file);
  ASSERT_FALSE(exchanges.empty()) << file;
  FakeTransport control;
  control.setMaxReadChunk(1);
  MdcClient client(control);
  for (const auto& e : exchanges)
  {
    SCOPED_TRACE(file + ":" + std::to_string(e.line) + " " + e.query);
    const auto query = parseReadOnlyQuery(e.query);
    ASSERT_TRUE(query) << "not a read-only query";
    control.clearWritten();
    control.onWrite([&e](FakeTransport& f, const std::vector<uint8_t>&) { f.feed(e.reply); });
    const uint64_t foreign_before = client.stats().foreign;
    const bool unanswered =
        std::any_of(e.expect.begin(), e.expect.end(), [](const auto& kv) { return kv.first == "unanswered"; });
    if (unanswered)
    {
      EXPECT_THROW(client.request(*query, 200ms), TimeoutError);
      continue;
    }
    Reply reply;
    try
    {
      reply = client.request(*query, 2000ms);
    }
    catch (const Error& error)
    {
      ADD_FAILURE() << error.what();
      continue;
    }
    // What went out is the query in the control's upper case, ended by CR LF.
    const auto written = control.written();
    EXPECT_EQ(std::string(written.begin(), written.end()), query->text() + "\r\n");
    ASSERT_TRUE(reply.answered);
    EXPECT_EQ(*reply.answered, *query);
    for (const auto& [key, want] : e.expect)
    {
      SCOPED_TRACE("expect " + key + "=" + want);
      try
      {
        check(key, want, reply, client.stats().foreign - foreign_before);
      }
      catch (const ProtocolError& error)
      {
        ADD_FAILURE() << "\"" << reply.line << "\": " << error.what();
      }
    }
  }
}
}  // namespace

TEST(MdcFixtures, NgcCommandTableExamples)
{
  play("ngc_command_table.mdcwire");
}

TEST(MdcFixtures, NgcRepliesAsClientsInUseReadThem)
{
  play("ngc_client_reads.mdcwire");
}

TEST(MdcFixtures, ClassicSerialPort)
{
  play("classic_serial.mdcwire");
}

TEST(MdcFixtures, SpellingsOfAnotherAdapter)
{
  play("trakhound_variants.mdcwire");
}

TEST(MdcFixtures, EveryFixtureFileIsPlayedAndNamedInTheReadme)
{
  // A fixture added without a test, or without its source in README.md, fails here.
  const std::set<std::string> played = {"ngc_command_table", "ngc_client_reads", "classic_serial",
                                        "trakhound_variants"};
  std::ifstream readme(std::string(MDC_TEST_DATA) + "/README.md");
  ASSERT_TRUE(readme);
  std::stringstream text;
  text << readme.rdbuf();
  for (const auto& name : played)
    EXPECT_NE(text.str().find("### " + name), std::string::npos) << name << " has no entry in README.md";
  size_t files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(MDC_TEST_DATA))
  {
    if (entry.path().extension() != ".mdcwire")
      continue;
    ++files;
    EXPECT_TRUE(played.count(entry.path().stem().string())) << entry.path() << " is not played by any test";
  }
  EXPECT_EQ(files, played.size());
}
