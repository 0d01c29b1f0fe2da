// HTTP for an MTConnect client: a response parser fed with bytes as they arrive (Boost.Beast's
// parser: status line, headers, Content-Length or chunked bodies), the multipart framing of an
// agent's streaming /sample answer (multipart/mixed or multipart/x-mixed-replace, each part with
// its own headers), and a client that sends GET requests over a Transport.
#pragma once

#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>

#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge::mtconnect
{
/// \brief Bounds on what an agent may send, so that a broken or hostile peer cannot exhaust memory.
struct HttpLimits
{
  size_t max_header_bytes = size_t{16} * 1024;
  size_t max_document_bytes = 16u << 20u;  ///< one XML document (a body or one part of a stream)
};

/// \brief Status and the headers the client uses.
struct ResponseHead
{
  unsigned status = 0;
  std::string reason;
  std::string content_type;
  bool keep_alive = false;
  bool chunked = false;
  /// \returns the multipart boundary of the content type, or empty when it is not multipart.
  std::string multipartBoundary() const;
};

/// \brief Parses one HTTP response from bytes fed in pieces of any size. Not thread-safe.
class ResponseParser
{
 public:
  /// Called with each piece of the body, after the chunked framing is removed.
  using BodySink = std::function<void(std::string_view piece)>;
  /// Called once the status line and headers are parsed, before any of the body.
  using HeadSink = std::function<void(const ResponseHead& head)>;
  ResponseParser(BodySink sink, const HttpLimits& limits = {}, HeadSink on_head = {});
  ~ResponseParser();
  ResponseParser(const ResponseParser&) = delete;
  ResponseParser& operator=(const ResponseParser&) = delete;

  /// \brief Parses \p data. \throws ProtocolError when the bytes are not an HTTP response.
  void feed(std::string_view data);
  /// \brief The peer closed the connection. \throws ProtocolError if the response is not whole.
  void feedEnd();
  bool headDone() const;
  const ResponseHead& head() const { return head_; }
  /// \returns true once the whole response (its last chunk, or Content-Length bytes) arrived.
  bool done() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  ResponseHead head_;
  std::string pending_;  // bytes the parser has not consumed yet
  void pump();
};

/// \brief Splits a multipart body into its parts' bodies. Not thread-safe.
class MultipartSplitter
{
 public:
  using PartSink = std::function<void(std::string&& body)>;
  MultipartSplitter(std::string boundary, size_t max_part_bytes);
  /// \brief Takes the next piece of the body; calls \p sink for each part completed.
  /// \throws ProtocolError on a part over the limit or bytes that are not multipart framing.
  void feed(std::string_view piece, const PartSink& sink);

 private:
  enum class State
  {
    kBoundary,
    kHeaders,
    kBody
  };
  bool step(const PartSink& sink);
  std::string delimiter_;  // "--" + boundary
  size_t max_part_bytes_;
  std::string buffer_;
  State state_ = State::kBoundary;
  long long content_length_ = -1;
};

/// \brief A response read whole.
struct Response
{
  ResponseHead head;
  std::string body;
};

/// \brief GET requests to one agent. Opens a connection per request unless the agent keeps it
/// alive. Thread-safe for interrupt() only.
class HttpClient
{
 public:
  using Connector = std::function<std::unique_ptr<Transport>()>;
  /// \param host_header the Host header ("10.0.0.5:8082")
  HttpClient(std::string host_header, Connector connect, HttpLimits limits = {});

  /// \brief GET \p target, the whole answer. \throws LinkError, TimeoutError (nothing for
  /// \p idle_timeout), ProtocolError, CancelledError after interrupt().
  Response get(const std::string& target, Milliseconds idle_timeout);

  /// What stream() found.
  struct StreamEnd
  {
    ResponseHead head;
    bool multipart = false;
    std::string body;  ///< the whole body when the answer was not multipart (a refused stream)
  };
  /// \brief GET \p target that the agent answers with a multipart stream: \p on_part gets each
  /// part's body as it completes, until it returns false, the agent ends the stream or the link
  /// fails (thrown as for get(); an agent that vanishes mid-stream is a LinkError).
  StreamEnd stream(const std::string& target, Milliseconds idle_timeout,
                   const std::function<bool(std::string&& part)>& on_part);

  /// \brief Makes the request in progress (and the next) throw CancelledError.
  void interrupt();
  /// \brief Clears interrupt() for the next session.
  void reset();
  const HttpLimits& limits() const { return limits_; }

 private:
  Transport& open();
  void send(Transport& link, const std::string& target);
  static void readInto(Transport& link, ResponseParser& parser, Milliseconds idle_timeout,
                       const std::function<bool()>& more);
  void release(bool keep_alive);

  std::string host_;
  Connector connect_;
  HttpLimits limits_;
  std::mutex mutex_;  // guards link_ and interrupted_
  std::shared_ptr<Transport> link_;
  bool interrupted_ = false;
};
}  // namespace cnc_bridge::mtconnect
