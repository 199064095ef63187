// The server's HTTP port (vistream-server --http-port): health for load
// balancers and orchestrators, metrics for Prometheus, and the PVS as JSON
// for renderers in any language. Boost.Beast on the server's io_context.
//
//   GET /healthz                 200 "ok" while serving, 503 once stopping
//   GET /metrics                 Prometheus text format 0.0.4: sessions,
//                                bytes sent, PVS cache, visibility work and
//                                its latency histograms, send queues,
//                                rejected sessions by reason, CPU
//   GET /pvs?point=x,y,z         the PVS of the view cell holding a point
//   GET /pvs?cell=i,j,k          (file coordinates) or of a grid cell, as
//                                {"cell":[i,j,k],"box":[...],"faces":[...]}
//                                (face IDs, ascending)
//
// Every connection has the shape of a stream session: one request read at a
// time (header and body bounded, a deadline for the whole request), the
// answer written, the next read on keep-alive; the PVS is computed on the
// server's worker pool (or read from its database) and answered on the
// connection's strand. Bad requests get 400 (a query naming what is wrong),
// unknown paths 404, other methods 405; a connection that stalls is closed.
// Nothing a client sends here disturbs the stream sessions.
//
// Thread safety: start() and stop() from any thread; the endpoint's work
// runs on the server's io_context.
#pragma once

#include <boost/asio/ip/tcp.hpp>
#include <cstdint>
#include <memory>
#include <string>

namespace vistream {

class StreamServer;

class HttpEndpoint {
 public:
  HttpEndpoint(StreamServer& server, const std::string& bindAddress, uint16_t port);
  ~HttpEndpoint();
  HttpEndpoint(const HttpEndpoint&) = delete;
  HttpEndpoint& operator=(const HttpEndpoint&) = delete;

  // Binds and starts accepting; throws InputError when the address is unusable.
  void start();
  void stop();
  uint16_t port() const { return port_; }

  // The metrics page (also what /metrics answers).
  std::string metricsText() const;

 private:
  void accept();

  StreamServer& server_;
  std::string bindAddress_;
  uint16_t requestedPort_ = 0, port_ = 0;
  boost::asio::ip::tcp::acceptor acceptor_;
};

}  // namespace vistream
