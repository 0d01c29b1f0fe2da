// Seeded fault injection over any Transport (see faulty_transport.h).
#include "testing/faulty_transport.h"

#include <sstream>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
FaultSettings FaultSettings::parse(const std::string& text)
{
  FaultSettings settings;
  std::istringstream items(text);
  std::string item;
  while (std::getline(items, item, ','))
  {
    if (item.empty())
      continue;
    const size_t eq = item.find('=');
    if (eq == std::string::npos)
      throw ConfigError("fault setting '" + item + "' is not key=value");
    const std::string key = item.substr(0, eq);
    double value = 0;
    try
    {
      size_t used = 0;
      value = std::stod(item.substr(eq + 1), &used);
      if (used != item.size() - eq - 1)
        throw std::invalid_argument(item);
    }
    catch (const std::exception&)
    {
      throw ConfigError("fault setting '" + item + "' has no number after '='");
    }
    if (key == "seed")
    {
      settings.seed = static_cast<uint32_t>(value);
      continue;
    }
    if (key == "read")
    {
      settings.on_read = value != 0;
      continue;
    }
    if (value < 0 || value > 1)
      throw ConfigError("fault probability '" + item + "' is outside 0..1");
    if (key == "flip")
      settings.flip = value;
    else if (key == "drop")
      settings.drop = value;
    else if (key == "dup" || key == "duplicate")
      settings.duplicate = value;
    else if (key == "lose")
      settings.lose_write = value;
    else
      throw ConfigError("unknown fault '" + key + "' (flip, drop, dup, lose, read, seed)");
  }
  return settings;
}

FaultyTransport::FaultyTransport(Transport& inner, FaultSettings settings)
    : ForwardingTransport(inner), settings_(settings), random_(settings.seed)
{
}

void FaultyTransport::damage(const uint8_t* in, size_t size, std::string& out)
{
  std::uniform_real_distribution<double> chance(0.0, 1.0);
  std::uniform_int_distribution<int> mask(1, 255);
  for (size_t i = 0; i < size; ++i)
  {
    uint8_t byte = in[i];
    if (settings_.drop > 0 && chance(random_) < settings_.drop)
    {
      ++counts_.dropped;
      continue;
    }
    if (settings_.flip > 0 && chance(random_) < settings_.flip)
    {
      byte ^= static_cast<uint8_t>(mask(random_));
      ++counts_.flipped;
    }
    out.push_back(static_cast<char>(byte));
    if (settings_.duplicate > 0 && chance(random_) < settings_.duplicate)
    {
      out.push_back(static_cast<char>(byte));
      ++counts_.duplicated;
    }
  }
}

size_t FaultyTransport::read(uint8_t* buffer, size_t size, Milliseconds timeout)
{
  if (!settings_.on_read)
  {
    return inner_.read(buffer, size, timeout);
  }
  // Read one byte at a time so a duplicate always fits the caller's buffer (kept for the next read).
  std::unique_lock<std::mutex> lock(mutex_, std::defer_lock);
  for (;;)
  {
    uint8_t raw = 0;
    const size_t n = inner_.read(&raw, 1, timeout);
    if (n == 0)
      return 0;
    std::string out;
    lock.lock();
    damage(&raw, 1, out);
    lock.unlock();
    if (out.empty())
      continue;  // dropped: wait for the next byte
    buffer[0] = static_cast<uint8_t>(out[0]);
    if (out.size() > 1 && size > 1)
    {
      buffer[1] = static_cast<uint8_t>(out[1]);
      return 2;
    }
    return 1;
  }
}

void FaultyTransport::write(const uint8_t* data, size_t size, Milliseconds timeout)
{
  std::string out;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    std::uniform_real_distribution<double> chance(0.0, 1.0);
    if (settings_.lose_write > 0 && chance(random_) < settings_.lose_write)
    {
      ++counts_.lost_writes;
      return;
    }
    damage(data, size, out);
  }
  if (!out.empty())
  {
    inner_.write(reinterpret_cast<const uint8_t*>(out.data()), out.size(), timeout);
  }
}

FaultCounts FaultyTransport::counts() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return counts_;
}
}  // namespace cnc_bridge
