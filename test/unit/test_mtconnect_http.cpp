// HTTP framing of the MTConnect client on the reference agent's recorded answers: Content-Length
// and chunked bodies, the multipart stream, fed in pieces split at every awkward place.
#include <gtest/gtest.h>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mtconnect/documents.h"
#include "cnc_bridge/mtconnect/http.h"
#include "mtconnect_fixtures.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mtconnect;
using cnc_bridge::mtconnect::testing::fixture;
using cnc_bridge::mtconnect::testing::parseResponse;

TEST(MtconnectHttp, ProbeIsOneWholeDocument)
{
  const auto r = parseResponse(fixture("probe.http"));
  EXPECT_TRUE(r.done);
  EXPECT_EQ(r.head.status, 200u);
  EXPECT_NE(r.head.content_type.find("xml"), std::string::npos);
  EXPECT_TRUE(r.head.multipartBoundary().empty());
  ASSERT_GT(r.body.size(), 1000u);
  EXPECT_EQ(r.body.find("<?xml"), 0u);
  EXPECT_EQ(parseDocument(r.body).kind, DocumentKind::kDevices);
}

TEST(MtconnectHttp, AnyPieceSizeGivesTheSameBody)
{
  const std::string bytes = fixture("current.http");
  const auto whole = parseResponse(bytes);
  ASSERT_GT(whole.body.size(), 500u);
  for (size_t piece : {1u, 2u, 3u, 7u, 64u, 1000u})
  {
    const auto r = parseResponse(bytes, piece);
    EXPECT_TRUE(r.done) << piece;
    EXPECT_EQ(r.body, whole.body) << "pieces of " << piece;
  }
}

TEST(MtconnectHttp, StreamSplitsIntoItsPartsWhereverTheBytesAreCut)
{
  const std::string bytes = fixture("stream.http");
  const auto whole = parseResponse(bytes, 0, false);
  EXPECT_EQ(whole.head.status, 200u);
  EXPECT_TRUE(whole.head.chunked);
  ASSERT_FALSE(whole.head.multipartBoundary().empty());
  ASSERT_GE(whole.parts.size(), 5u);
  for (const auto& part : whole.parts)
  {
    const Document doc = parseDocument(part);
    EXPECT_EQ(doc.kind, DocumentKind::kStreams);
  }
  // Every piece size from 1 to 97 bytes cuts the chunk-size lines, the CRLFs, the boundary and
  // the part headers at every offset.
  for (size_t piece = 1; piece < 98; ++piece)
  {
    const auto r = parseResponse(bytes, piece, false);
    ASSERT_EQ(r.parts, whole.parts) << "pieces of " << piece;
  }
}

TEST(MtconnectHttp, ChunkSizeLineCutInTwo)
{
  const std::string head = "HTTP/1.1 200 OK\r\nContent-Type: text/xml\r\nTransfer-Encoding: chunked\r\n\r\n";
  std::string body;
  ResponseParser parser([&](std::string_view piece) { body.append(piece); });
  parser.feed(head + "1");
  parser.feed("0\r\n0123456789ABCDEF\r");
  parser.feed("\n0\r\n\r\n");
  EXPECT_TRUE(parser.done());
  EXPECT_EQ(body, "0123456789ABCDEF");
}

TEST(MtconnectHttp, MultipartWithoutContentLengthEndsAtTheNextBoundary)
{
  MultipartSplitter splitter("abc", 1000);
  std::vector<std::string> parts;
  auto sink = [&](std::string&& p) { parts.push_back(p); };
  splitter.feed("preamble\r\n--abc\r\nContent-Type: text/xml\r\n\r\n<a/>", sink);
  splitter.feed("\r\n--ab", sink);
  EXPECT_EQ(parts.size(), 0u);  // the delimiter is not whole yet
  splitter.feed("c\r\nContent-Type: text/xml\r\n\r\n<b/>\r\n--abc--\r\n", sink);
  ASSERT_EQ(parts.size(), 2u);
  EXPECT_EQ(parts[0], "<a/>");
  EXPECT_EQ(parts[1], "<b/>");
}

TEST(MtconnectHttp, BoundaryFromTheContentType)
{
  ResponseHead head;
  head.content_type = "multipart/x-mixed-replace; boundary=\"Ab12\"";
  EXPECT_EQ(head.multipartBoundary(), "Ab12");
  head.content_type = "multipart/mixed;boundary=e3f4;charset=utf-8";
  EXPECT_EQ(head.multipartBoundary(), "e3f4");
  head.content_type = "text/xml";
  EXPECT_EQ(head.multipartBoundary(), "");
}

TEST(MtconnectHttp, OversizedPartIsRefused)
{
  MultipartSplitter splitter("b", 100);
  auto sink = [](std::string&&) { FAIL() << "no part may come out"; };
  EXPECT_THROW(splitter.feed("--b\r\nContent-length: 5000\r\n\r\n", sink), ProtocolError);
  MultipartSplitter unbounded("b", 100);
  EXPECT_THROW(unbounded.feed("--b\r\n\r\n" + std::string(5000, 'x'), sink), ProtocolError);
}

TEST(MtconnectHttp, GarbageIsAProtocolError)
{
  ResponseParser parser([](std::string_view) {});
  try
  {
    parser.feed("SSH-2.0-OpenSSH_9.2\r\n\r\n");
    FAIL() << "garbage accepted";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_NE(std::string(e.what()).find("malformed"), std::string::npos) << e.what();
  }
}

TEST(MtconnectHttp, HugeHeaderIsRefused)
{
  HttpLimits limits;
  limits.max_header_bytes = 1024;
  ResponseParser parser([](std::string_view) {}, limits);
  parser.feed("HTTP/1.1 200 OK\r\n");
  EXPECT_THROW(parser.feed("X-Filler: " + std::string(4096, 'a') + "\r\n"), ProtocolError);
}

TEST(MtconnectHttp, TruncatedAnswerIsALinkErrorAtTheClose)
{
  const std::string bytes = fixture("probe.http");
  ResponseParser parser([](std::string_view) {});
  parser.feed(bytes.substr(0, bytes.size() / 2));
  EXPECT_FALSE(parser.done());
  try
  {
    parser.feedEnd();
    FAIL() << "a cut answer accepted";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("middle"), std::string::npos) << e.what();
  }
}

TEST(MtconnectHttp, StreamCutByTheAgentStoppingEndsInALinkError)
{
  // Recorded: the agent was stopped during a stream; it sent no last chunk.
  const std::string bytes = fixture("stream_agent_stopped.http");
  std::vector<std::string> parts;
  std::unique_ptr<MultipartSplitter> splitter;
  ResponseParser parser(
      [&](std::string_view body) { splitter->feed(body, [&](std::string&& p) { parts.push_back(p); }); }, {},
      [&](const ResponseHead& head)
      { splitter = std::make_unique<MultipartSplitter>(head.multipartBoundary(), 1u << 20u); });
  parser.feed(bytes);
  EXPECT_GE(parts.size(), 1u);
  EXPECT_FALSE(parser.done());
  EXPECT_THROW(parser.feedEnd(), LinkError);
}

TEST(MtconnectHttp, ConnectionClosedBeforeAnyByteIsALinkError)
{
  // An agent that accepts and closes without a byte (found by fuzz_mtconnect: Beast's parser may
  // not be told the end of a stream it never saw a byte of; without NDEBUG it aborts).
  ResponseParser parser([](std::string_view) {});
  try
  {
    parser.feedEnd();
    FAIL() << "an answer of no bytes was taken as complete";
  }
  catch (const LinkError& e)
  {
    EXPECT_NE(std::string(e.what()).find("before answering"), std::string::npos) << e.what();
  }
  ResponseParser fed_nothing([](std::string_view) {});
  fed_nothing.feed("");
  EXPECT_THROW(fed_nothing.feedEnd(), LinkError);
}
