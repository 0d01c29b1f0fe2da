// libFuzzer target: what an MTConnect agent (or anything answering on its port) sends the client,
// and what the adapter makes of a machine's texts. The bytes are an HTTP response fed to the
// client's parser in pieces (Beast's parser, chunked framing, the multipart splitter), each body
// or part read as an MTConnect document and, when it holds a device or observations, applied to a
// machine model. The same bytes as a program name and a message go through the SHDR adapter's
// encoder, whose lines must stay one line each. Nothing may crash; bad input may only throw the
// suite's errors (ProtocolError, ConfigError).
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mtconnect/documents.h"
#include "cnc_bridge/mtconnect/http.h"
#include "cnc_bridge/mtconnect/machine_model.h"
#include "cnc_bridge/mtconnect/shdr.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mtconnect;

namespace
{
void readDocument(const std::string& body, MachineModel& model)
{
  try
  {
    const Document doc = parseDocument(body, 1u << 20u);
    if (!doc.devices.empty())
      model.setDevice(selectDevice(doc, ""));
    model.apply(doc.observations, doc.observations.size() % 2 == 0);
    model.activeConditions();
  }
  catch (const Error&)
  {
  }
}

void readResponse(const std::string& bytes, size_t piece)
{
  MachineModel model;
  std::unique_ptr<MultipartSplitter> splitter;
  try
  {
    ResponseParser parser(
        [&](std::string_view body)
        {
          if (splitter)
            splitter->feed(body, [&](std::string&& part) { readDocument(part, model); });
          else
            readDocument(std::string(body), model);
        },
        HttpLimits{},
        [&](const ResponseHead& head)
        {
          const std::string boundary = head.multipartBoundary();
          if (!boundary.empty())
            splitter = std::make_unique<MultipartSplitter>(boundary, 1u << 20u);
        });
    for (size_t at = 0; at < bytes.size(); at += piece)
      parser.feed(std::string_view(bytes).substr(at, piece));
    parser.feedEnd();
  }
  catch (const Error&)
  {
  }
}

void encode(const std::string& text)
{
  ShdrDevice device("m");
  MachineReport report;
  report.link_up = true;
  report.view.program = text;
  report.view.door = "OPEN";
  report.message = text;
  report.view.execution = Execution::kAlarm;
  for (const auto& line : device.update(report))
  {
    if (line.find('\n') != std::string::npos || line.find('\r') != std::string::npos)
      std::abort();  // a text cut the SHDR line: the agent would read the rest as other items
  }
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  if (size == 0)
    return 0;
  const std::string bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  readResponse(bytes, 1 + data[0] % 97);  // pieces cut anywhere, as TCP delivers them
  encode(bytes);
  return 0;
}
