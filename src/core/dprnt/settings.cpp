// makeInput (see settings.h).
#include "cnc_bridge/dprnt/settings.h"

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace dprnt
{
std::unique_ptr<DprntInput> makeInput(const InputSettings& settings)
{
  switch (settings.kind)
  {
    case InputSettings::Kind::kLink:
      return std::make_unique<StreamInput>(linkFactory(settings.link), settings.link.hardwareId(), settings.backoff);
    case InputSettings::Kind::kFile:
      return std::make_unique<FileInput>(settings.file, settings.from_start, settings.poll_period, settings.backoff);
    case InputSettings::Kind::kTopic:
      break;
  }
  throw ConfigError("DPRNT input from a topic is built by the node, not the core");
}
}  // namespace dprnt
}  // namespace cnc_bridge
