// The one boundary every service call and action goal of every node goes through
// (docs/ROS_INTERFACE.md, "How a call fails"). A handler reports what it expects to go wrong in
// its answer; anything else it throws (a library's std::ios_base::failure, std::bad_alloc, a bug)
// stops here: a service answers success false with a message that names the service, the request
// and the error (a service without success/message fields returns false, which the caller sees as
// an error, and the message is logged), and a goal is aborted with that message
// (SingleGoalActionServer, dnc_node's ~transfer). What the call held (a transfer slot, the port,
// the port lock) is released by its scope guards on the way out, so the next call is served at
// once: a node never dies or wedges on a request.
#pragma once

#include <ros/ros.h>

#include <exception>
#include <functional>
#include <sstream>
#include <string>
#include <type_traits>
#include <utility>

namespace cnc_bridge
{
namespace boundary
{
/// \brief The text of the exception being handled. Call only inside a catch block.
inline std::string currentExceptionText()
{
  try
  {
    throw;
  }
  catch (const std::exception& e)
  {
    return e.what();
  }
  catch (...)
  {
    return "an exception that is not a std::exception";
  }
}

/// \brief A request or goal in one line of at most \p limit characters ("file: somedir, protocol:
/// xmodem"): its fields as rosmsg shows them, lines joined, a long value cut.
template <class Message>
std::string describe(const Message& message, std::size_t limit = 240)
{
  std::ostringstream out;
  ros::message_operations::Printer<Message>::stream(out, "", message);
  std::string text;
  for (const char c : out.str())
  {
    if (c == '\n')
    {
      if (!text.empty() && text.back() != ' ')
        text += ", ";
      continue;
    }
    text += (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) ? '?' : c;
    if (text.size() > limit)
      return text.substr(0, limit) + "...";
  }
  while (!text.empty() && (text.back() == ' ' || text.back() == ','))
    text.pop_back();
  return text;
}

/// \brief "<what> failed: <error> (...)": the answer to a call that ended by an unexpected error.
inline std::string failure(const std::string& what, const std::string& error)
{
  return what + " failed: " + error +
         " (an unexpected error, caught at the node's request boundary: what the call held is released and "
         "the node goes on serving)";
}

/// \brief "<name> (<request>)", or "<name>" for an empty request.
template <class Message>
std::string callName(const std::string& name, const Message& request)
{
  const std::string fields = describe(request);
  return fields.empty() ? name : name + " (" + fields + ")";
}

/// True for a response with `bool success` and `string message` fields.
template <class T, class = void>
struct HasSuccessAndMessage : std::false_type
{
};
template <class T>
struct HasSuccessAndMessage<
    T, std::void_t<decltype(std::declval<T&>().success = false), decltype(std::declval<T&>().message = std::string())>>
    : std::true_type
{
};

/// \brief Runs `handler(request, response)`; an exception it throws becomes the failed answer: the
/// response reset and, where it has them, success false and the message (then true is returned,
/// so the caller gets the answer); otherwise false (the caller sees the call fail). Logged either way.
/// \param service the resolved service name, for the message.
template <class Request, class Response, class Handler>
bool answerGuarded(const std::string& service, Request& request, Response& response, Handler&& handler)
{
  try
  {
    return handler(request, response);
  }
  catch (...)
  {
    const std::string message = failure(callName(service, request), currentExceptionText());
    ROS_ERROR_STREAM(message);
    response = Response();
    if constexpr (HasSuccessAndMessage<Response>::value)
    {
      response.success = false;
      response.message = message;
      return true;
    }
    else
    {
      return false;
    }
  }
}
}  // namespace boundary

/// \brief advertiseService through the request boundary (boundary::answerGuarded): a handler taking
/// `(Request&, Response&)`, e.g. a lambda. Every node advertises its services this way.
template <class Service, class Handler>
ros::ServiceServer advertiseGuardedService(ros::NodeHandle nh, const std::string& name, Handler handler)
{
  using Request = typename Service::Request;
  using Response = typename Service::Response;
  const std::string service = nh.resolveName(name);
  return nh.advertiseService<Request, Response>(
      name, [service, handler = std::move(handler)](Request& request, Response& response) mutable
      { return boundary::answerGuarded(service, request, response, handler); });
}

/// \brief advertiseGuardedService for a member function `bool T::f(Request&, Response&)`.
template <class T, class Request, class Response>
ros::ServiceServer advertiseGuardedService(ros::NodeHandle nh, const std::string& name,
                                           bool (T::*method)(Request&, Response&), T* object)
{
  const std::string service = nh.resolveName(name);
  return nh.advertiseService<Request, Response>(name,
                                                [service, method, object](Request& request, Response& response)
                                                {
                                                  return boundary::answerGuarded(service, request, response,
                                                                                 [&](Request& q, Response& s)
                                                                                 { return (object->*method)(q, s); });
                                                });
}

/// \brief advertiseGuardedService for a member function that takes the ros::ServiceEvent (for the
/// caller's name).
template <class T, class Request, class Response>
ros::ServiceServer advertiseGuardedService(ros::NodeHandle nh, const std::string& name,
                                           bool (T::*method)(ros::ServiceEvent<Request, Response>&), T* object)
{
  using Event = ros::ServiceEvent<Request, Response>;
  const std::string service = nh.resolveName(name);
  return nh.advertiseService<Event>(name,
                                    [service, method, object](Event& event)
                                    {
                                      Request& request = const_cast<Request&>(event.getRequest());
                                      return boundary::answerGuarded(service, request, event.getResponse(),
                                                                     [&](Request&, Response&)
                                                                     { return (object->*method)(event); });
                                    });
}
}  // namespace cnc_bridge
