// libFuzzer target: the program-request recogniser on arbitrary text (punched programs, DPRNT
// lines). Must not crash; a recognised request's answer program must carry the request's number.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/programs/program_request.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  using namespace cnc_bridge::programs;
  const std::string text(reinterpret_cast<const char*>(data), size);
  for (const bool bare : {false, true})
  {
    if (const auto request = recogniseRequest(text, bare))
    {
      if (readHeader(answerProgram(request->number, request->word, text)).number != request->number)
        std::abort();
    }
  }
  return 0;
}
