// File-level XModem transfers: end-of-block conversion, padding, atomic writes (file_transfer.h).
#include "cnc_bridge/xmodem/file_transfer.h"

#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/regular_file.h"

namespace cnc_bridge
{
namespace xmodem
{
std::vector<uint8_t> toWire(const std::string& file_contents, const TextOptions& options)
{
  const std::string wire = options.binary ? file_contents : toControlEob(file_contents, options.control_eob);
  return std::vector<uint8_t>(wire.begin(), wire.end());
}

std::string fromWire(std::vector<uint8_t> payload, const TextOptions& options)
{
  if (options.binary)
  {
    return std::string(payload.begin(), payload.end());
  }
  stripSubPadding(payload);
  return fromControlEob(std::string(payload.begin(), payload.end()), options.control_eob, options.file_eob);
}

Config withEobReading(Config config, const TextOptions& options)
{
  config.eob_checksum = options.binary ? EobChecksum::kWire : options.eob_checksum;
  config.eob = options.control_eob;
  return config;
}

FileResult sendFile(Transport& link, const std::string& path, Mode mode, const Config& config,
                    const TextOptions& options, const ProgressCallback& progress, const std::atomic<bool>* cancel,
                    Stats* stats, const ContentCheck& check)
{
  const std::string contents = RegularFile(path).readAll(config.max_bytes, config.max_bytes_name);
  if (check)
    check(contents);
  Sender sender(link, mode, withEobReading(config, options), cancel);
  FileResult result;
  try
  {
    result.stats = sender.send(toWire(contents, options), progress);
  }
  catch (...)
  {
    if (stats)
      *stats = sender.stats();
    throw;
  }
  if (stats)
    *stats = result.stats;
  result.file_bytes = contents.size();
  result.path = path;
  result.message = "sent " + path + ": " + result.stats.summary();
  return result;
}

FileResult receiveFile(Transport& link, const std::string& path, Mode mode, const Config& config,
                       const TextOptions& options, const ProgressCallback& progress, const std::atomic<bool>* cancel,
                       Stats* stats)
{
  // Opened first: an unwritable destination fails before the control is asked for anything.
  AtomicFileWriter writer(path);
  Receiver receiver(link, mode, withEobReading(config, options), cancel);
  std::vector<uint8_t> payload;
  try
  {
    payload = receiver.receive(progress);
  }
  catch (...)
  {
    if (stats)
      *stats = receiver.stats();
    throw;
  }
  if (stats)
    *stats = receiver.stats();
  const std::string contents = fromWire(std::move(payload), options);
  writer.write(contents);
  writer.commit();
  FileResult result;
  result.stats = receiver.stats();
  result.file_bytes = contents.size();
  result.path = path;
  result.message = "received " + path + " (" + std::to_string(contents.size()) + " bytes): " + result.stats.summary();
  return result;
}
}  // namespace xmodem
}  // namespace cnc_bridge
