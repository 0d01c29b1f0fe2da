// OpenDNC's capture of a real Haas Classic's XModem exchanges
// (test/data/xmodem/haas_xmodem_capture.json, the serial sniffer of OpenDNC's appendix), read as
// the tests that replay it need it: the transmissions of one exchange, in order, with who sent each.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <string>
#include <vector>

namespace cnc_bridge::test
{
using Bytes = std::vector<uint8_t>;

inline Bytes fromHex(const std::string& hex)
{
  Bytes out;
  for (size_t i = 0; i + 1 < hex.size(); i += 2)
    out.push_back(static_cast<uint8_t>(std::stoi(hex.substr(i, 2), nullptr, 16)));
  return out;
}

struct CaptureEvent
{
  bool from_pc;
  Bytes bytes;
};

inline std::vector<CaptureEvent> capture(const std::string& exchange)
{
  const YAML::Node root = YAML::LoadFile(std::string(XMODEM_TEST_DATA) + "/haas_xmodem_capture.json");
  std::vector<CaptureEvent> events;
  for (const auto& event : root["exchanges"][exchange]["events"])
    events.push_back({event["from"].as<std::string>() == "pc", fromHex(event["hex"].as<std::string>())});
  return events;
}
}  // namespace cnc_bridge::test
