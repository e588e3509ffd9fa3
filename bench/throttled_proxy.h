// A TCP proxy on 127.0.0.1 that makes loopback look like a network link: each
// byte arrives a one-way delay late, and what the server sends is paced to
// the client's bandwidth and, across all proxies sharing a trunk, to the
// server's. One proxy per client, so each client has its own link.
//
// Pacing is that of a route through two links: the trunk (the server's,
// shared by all proxies) and then the client's own. A chunk from the server
// crosses the trunk when it is free, then the client's link when that is
// free, occupying each for its size over its rate, and arrives the delay
// after it has left. The proxy takes the next chunk from the server only
// when the client's link is about to drain (as TCP holds a sender to its
// bottleneck), so the trunk carries what the clients' links can take, and
// a client never waits for another's link. Requests (client to server) are
// only delayed: they are small.
#pragma once

#include <netinet/in.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace octocosm {

// 127.0.0.1:`port` (0: any free port, for bind).
sockaddr_in LoopbackAddress(int port);

// A link's occupancy: when it is next free.
class PacedLink {
 public:
  explicit PacedLink(double bytes_per_second) : bytes_per_second_(bytes_per_second) {}
  double bytes_per_second() const { return bytes_per_second_; }

 private:
  friend class ThrottledProxy;
  double bytes_per_second_;
  std::mutex mutex_;
  std::chrono::steady_clock::time_point free_at_{};
};

class ThrottledProxy {
 public:
  // Forwards connections to 127.0.0.1:`server_port`. `trunk` may be shared
  // by several proxies (a rate of 0 or less: unlimited).
  ThrottledProxy(int server_port, double round_trip_s, double client_bytes_per_second,
                 std::shared_ptr<PacedLink> trunk);
  ~ThrottledProxy();
  ThrottledProxy(const ThrottledProxy&) = delete;
  ThrottledProxy& operator=(const ThrottledProxy&) = delete;

  int port() const { return port_; }
  // Bytes delivered to the client so far.
  std::uint64_t bytes_to_client() const { return bytes_to_client_.load(); }
  // HTTP requests forwarded to the server so far (each ends its headers with
  // an empty line; the clients' requests have no bodies).
  std::uint64_t requests() const { return requests_.load(); }

 private:
  void AcceptLoop();
  // One connection: connects to the server and relays both ways until both close.
  void Relay(int client);
  void Pump(int from, int to, bool to_client);
  std::chrono::steady_clock::time_point Pace(std::size_t bytes);

  int server_port_;
  double one_way_delay_s_;
  PacedLink client_link_;
  std::shared_ptr<PacedLink> trunk_;
  int listener_ = -1;
  int port_ = 0;
  std::atomic<bool> stopping_{false};
  std::atomic<std::uint64_t> bytes_to_client_{0};
  std::atomic<std::uint64_t> requests_{0};
  std::thread acceptor_;
  std::mutex threads_mutex_;
  std::vector<std::thread> threads_;
  std::vector<int> sockets_;
};

}  // namespace octocosm
