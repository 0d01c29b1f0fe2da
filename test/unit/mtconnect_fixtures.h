// The responses recorded from the reference agent (test/data/mtconnect/README.md), for the unit
// tests: the raw bytes of a file, and its HTTP body taken apart by the client's own parser.
#pragma once

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "cnc_bridge/mtconnect/http.h"

namespace cnc_bridge::mtconnect::testing
{
inline std::string fixture(const std::string& name)
{
  const std::string path = std::string(MTCONNECT_TEST_DATA) + "/" + name;
  std::ifstream in(path, std::ios::binary);
  if (!in)
    throw std::runtime_error("missing fixture " + path);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

/// What a recorded response holds: its head, its body (unchunked) and, for a stream, its parts.
struct Parsed
{
  ResponseHead head;
  std::string body;
  std::vector<std::string> parts;
  bool done = false;
};

/// \brief Feeds \p bytes to the parser in pieces of \p piece bytes (0: all at once).
inline Parsed parseResponse(const std::string& bytes, size_t piece = 0, bool end_of_stream = true)
{
  Parsed out;
  std::unique_ptr<MultipartSplitter> splitter;
  ResponseParser parser(
      [&](std::string_view body)
      {
        if (splitter)
          splitter->feed(body, [&](std::string&& part) { out.parts.push_back(std::move(part)); });
        else
          out.body.append(body);
      },
      HttpLimits{},
      [&](const ResponseHead& head)
      {
        const std::string boundary = head.multipartBoundary();
        if (!boundary.empty())
          splitter = std::make_unique<MultipartSplitter>(boundary, 1u << 20u);
      });
  const size_t step = piece == 0 ? bytes.size() : piece;
  for (size_t at = 0; at < bytes.size(); at += step)
    parser.feed(std::string_view(bytes).substr(at, step));
  if (end_of_stream)
    parser.feedEnd();
  out.head = parser.head();
  out.done = parser.done();
  return out;
}
}  // namespace cnc_bridge::mtconnect::testing
