// Simulator support: signal thread and announcement line.
#include "cnc_bridge/sim/sim_support.h"

#include <csignal>
#include <iostream>
#include <mutex>
#include <thread>
#include <vector>

namespace cnc_bridge
{
namespace sim
{
namespace
{
std::mutex callbacks_mutex;
std::vector<std::function<void()>> callbacks;
}  // namespace

StopSignal& installStopHandler()
{
  static StopSignal stop;
  static std::once_flag once;
  std::call_once(once,
                 []
                 {
                   sigset_t set;
                   sigemptyset(&set);
                   sigaddset(&set, SIGINT);
                   sigaddset(&set, SIGTERM);
                   pthread_sigmask(SIG_BLOCK, &set, nullptr);
                   std::thread(
                       [set]
                       {
                         int signal_number = 0;
                         sigwait(&set, &signal_number);
                         stop.stop();
                         std::lock_guard<std::mutex> lock(callbacks_mutex);
                         for (auto& callback : callbacks)
                         {
                           callback();
                         }
                       })
                       .detach();
                 });
  return stop;
}

void onStop(std::function<void()> callback)
{
  std::lock_guard<std::mutex> lock(callbacks_mutex);
  callbacks.push_back(std::move(callback));
}

void announce(const std::string& what, const std::string& where)
{
  std::cout << what << " " << where << std::endl;
}
}  // namespace sim
}  // namespace cnc_bridge
