#include "cnc_bridge/dnc/transfer_gate.h"

namespace cnc_bridge::dnc
{
bool TransferGate::tryReserve(const std::string& what)
{
  std::lock_guard<std::mutex> lock(mutex_);
  if (!reserveLocked(what, nullptr))
    return false;
  listen_stop_ = listening_;  // the listener leaves the port (waitForListenerToLeave)
  return true;
}

bool TransferGate::tryReserveForPunch(const std::string& what, std::string& running)
{
  std::lock_guard<std::mutex> lock(mutex_);
  return reserveLocked(what, &running);
}

bool TransferGate::waitToListen()
{
  std::unique_lock<std::mutex> lock(mutex_);
  changed_.wait(lock, [this] { return stop_listener_ || !busy_; });
  if (stop_listener_)
    return false;
  listening_ = true;
  listen_stop_ = false;
  return true;
}

void TransferGate::leftPort()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    listening_ = false;
  }
  changed_.notify_all();
}

void TransferGate::waitForListenerToLeave()
{
  std::unique_lock<std::mutex> lock(mutex_);
  listen_stop_ = listening_;
  changed_.wait(lock, [this] { return !listening_; });
}

void TransferGate::stopListener()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_listener_ = true;
    listen_stop_ = true;
  }
  changed_.notify_all();
}

void TransferGate::pauseListener(std::chrono::milliseconds pause)
{
  std::unique_lock<std::mutex> lock(mutex_);
  changed_.wait_for(lock, pause, [this] { return stop_listener_; });
}
}  // namespace cnc_bridge::dnc
