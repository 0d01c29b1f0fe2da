// libFuzzer target: program names, numbers and heads. The first byte picks a name pattern; the
// rest is a file name, a program head, a protected range and a store name at once. Must not crash;
// a number read from a name must format back to a name that reads the same number.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/programs/program_store.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  using namespace cnc_bridge::programs;
  if (size == 0)
    return 0;
  static const char* const kPatterns[] = {"O%05d.nc", "%d", "O%04d", "P%%%08d.min", "prog_%d.txt"};
  const NamePattern pattern(kPatterns[data[0] % 5]);
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (const auto number = pattern.number(text))
  {
    if (pattern.number(pattern.format(*number)) != number)
      std::abort();
  }
  const ProgramHeader header = readHeader(text);
  if (header.comment.find('\n') != std::string::npos)
    std::abort();
  try
  {
    NamePattern{text};
  }
  catch (const cnc_bridge::ConfigError&)
  {
  }
  try
  {
    const ProtectedRange range(text, false, "x");
    if (header.number)
      range.check("fuzz", pattern.number(text), header.number);
  }
  catch (const cnc_bridge::ConfigError&)
  {
  }
  catch (const cnc_bridge::DisabledError&)
  {
  }
  try
  {
    checkName(text);
    isTemporaryName(temporaryName(text, "t"));
  }
  catch (const cnc_bridge::ConfigError&)
  {
  }
  return 0;
}
