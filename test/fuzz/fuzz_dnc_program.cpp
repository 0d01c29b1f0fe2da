// libFuzzer target: arbitrary bytes as an NC program file through the drip-feed plan (line
// reader, character check, modal tracker, restart by line and by block number). Must not crash;
// a plan, when one is made, must count at least the bytes of the lines it sends.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dnc/drip_feed.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  using namespace cnc_bridge::dnc;
  // planDrip reads a file: one scratch file per fuzzing process, removed as the fuzzer exits.
  struct ScratchFile
  {
    std::string path = "/tmp/fuzz_dnc_program." + std::to_string(::getpid()) + ".nc";
    ~ScratchFile() { std::remove(path.c_str()); }
  };
  static const ScratchFile scratch;
  const std::string& path = scratch.path;
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr)
  {
    return 0;
  }
  std::fwrite(data, 1, size, file);
  std::fclose(file);
  DripOptions options;
  options.max_line_length = 256;
  options.rules.reject_lowercase = size > 0 && (data[0] & 1);
  for (const RestartPoint& restart : {RestartPoint{}, RestartPoint{3, ""}, RestartPoint{0, "N10"}})
  {
    try
    {
      const DripPlan plan = planDrip(path, options, restart);
      if (plan.total_bytes < plan.scan.body_bytes)
      {
        std::abort();
      }
    }
    catch (const cnc_bridge::ConfigError&)
    {
      // Refused with a message: the expected outcome for most random input.
    }
  }
  return 0;
}
