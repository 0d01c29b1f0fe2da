// What dprnt_node is set up from (read in the ROS layer by dprnt_params.cpp), and the input it
// names, built through the link factory. ROS-free.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "cnc_bridge/dprnt/input.h"
#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/link_factory.h"

namespace cnc_bridge
{
namespace dprnt
{
/// \brief Where DPRNT output arrives (docs/dprnt_node.md, input).
struct InputSettings
{
  enum class Kind
  {
    kLink,   ///< a serial port or a TCP connection: link
    kFile,   ///< a file the control appends to: file, from_start, poll_period
    kTopic,  ///< lines another node read (haas_mdc_node's forward_dprnt): topic; built by the node
  };
  Kind kind = Kind::kLink;
  LinkSettings link;
  std::string file;
  bool from_start = false;
  Milliseconds poll_period{50};
  std::string topic = "dprnt/port_lines";
  Backoff backoff;
};

/// \brief Everything else dprnt_node reads.
struct DprntSettings
{
  InputSettings input;
  size_t max_line_length = 256;        ///< longer lines are counted and skipped
  bool mask_parity = true;             ///< clear bit 7 of every byte
  std::string program_units = "inch";  ///< the programs' length unit, for rules without their own
  std::string rules_file;              ///< empty: raw and values only
  std::vector<double> work_offset;     ///< empty, or [x, y, z] m of the work frame to publish
};

/// \brief The input of a kLink or kFile setting.
/// \throws ConfigError for kTopic (the ROS layer builds that one) or invalid link settings.
std::unique_ptr<DprntInput> makeInput(const InputSettings& settings);
}  // namespace dprnt
}  // namespace cnc_bridge
