// A `cancelled` predicate for a JobHold wait running on another thread: it tells the test when the
// wait has begun (its first question), and answers "cancelled" once the test sets `cancel`.
#pragma once

#include <atomic>
#include <chrono>
#include <future>

#include "cnc_bridge/common/job_hold.h"

namespace cnc_bridge
{
namespace test
{
constexpr auto kPatience = std::chrono::seconds(10);  // a wait that must end ends long before this

struct CancelProbe
{
  std::promise<void> asked;
  std::atomic<bool> asked_once{false};
  std::atomic<bool> cancel{false};

  JobHold::Cancelled predicate()
  {
    return [this]
    {
      if (!asked_once.exchange(true))
      {
        asked.set_value();
      }
      return cancel.load();
    };
  }
};
}  // namespace test
}  // namespace cnc_bridge
