// The remote bench's link (bench/throttled_proxy.h): each client gets its own
// link's rate while the trunk they share has room, the trunk's rate among
// them when it has not, and every byte a one-way delay late. The figures in
// docs/REMOTE.md rest on this model. Bounds are wide (a loaded machine only
// slows a paced link down, never speeds it up), and the upper ones tight:
// a link never carries more than its rate.
#include "bench/throttled_proxy.h"

#include <arpa/inet.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <memory>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace octocosm {
namespace {

using Clock = std::chrono::steady_clock;

// A server on 127.0.0.1 that sends `bytes` bytes down every connection it
// accepts, then closes it.
class SendingServer {
 public:
  SendingServer(std::size_t bytes, int connections) : bytes_(bytes) {
    listener_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in address = LoopbackAddress(0);
    EXPECT_EQ(::bind(listener_, reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
    EXPECT_EQ(::listen(listener_, 16), 0);
    socklen_t length = sizeof address;
    ::getsockname(listener_, reinterpret_cast<sockaddr*>(&address), &length);
    port_ = ntohs(address.sin_port);
    acceptor_ = std::thread([this, connections] {
      for (int c = 0; c < connections; ++c) {
        const int fd = ::accept4(listener_, nullptr, nullptr, SOCK_CLOEXEC);
        if (fd < 0) return;
        senders_.emplace_back([this, fd] {
          const std::vector<char> data(bytes_, 'x');
          std::size_t done = 0;
          while (done < data.size()) {
            const ssize_t sent = ::send(fd, data.data() + done, data.size() - done, MSG_NOSIGNAL);
            if (sent <= 0) break;
            done += static_cast<std::size_t>(sent);
          }
          ::close(fd);
        });
      }
    });
  }
  ~SendingServer() {
    acceptor_.join();
    for (std::thread& t : senders_) t.join();
    ::close(listener_);
  }
  int port() const { return port_; }

 private:
  std::size_t bytes_;
  int listener_ = -1;
  int port_ = 0;
  std::thread acceptor_;
  std::vector<std::thread> senders_;
};

// What a client through `proxy_port` saw: the bytes, and the seconds to the
// first and to the last of them.
struct Received {
  std::size_t bytes = 0;
  double first_s = 0, all_s = 0;
};

Received Receive(int proxy_port) {
  Received r;
  const auto start = Clock::now();
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in address = LoopbackAddress(proxy_port);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0) return r;
  std::vector<char> buffer(1 << 16);
  for (;;) {
    const ssize_t got = ::recv(fd, buffer.data(), buffer.size(), 0);
    if (got <= 0) break;
    if (r.bytes == 0) r.first_s = std::chrono::duration<double>(Clock::now() - start).count();
    r.bytes += static_cast<std::size_t>(got);
  }
  r.all_s = std::chrono::duration<double>(Clock::now() - start).count();
  ::close(fd);
  return r;
}

// `clients` clients at once, each through its own proxy at `client_rate`,
// all sharing a trunk at `trunk_rate`, each receiving `bytes`.
std::vector<Received> ReceiveAtOnce(int clients, std::size_t bytes, double round_trip_s, double client_rate,
                                    double trunk_rate) {
  SendingServer server(bytes, clients);
  auto trunk = std::make_shared<PacedLink>(trunk_rate);
  std::vector<std::unique_ptr<ThrottledProxy>> proxies;
  for (int c = 0; c < clients; ++c) {
    proxies.push_back(std::make_unique<ThrottledProxy>(server.port(), round_trip_s, client_rate, trunk));
  }
  std::vector<Received> received(static_cast<std::size_t>(clients));
  std::vector<std::thread> threads;
  for (int c = 0; c < clients; ++c) {
    threads.emplace_back([&, c] { received[static_cast<std::size_t>(c)] = Receive(proxies[static_cast<std::size_t>(c)]->port()); });
  }
  for (std::thread& t : threads) t.join();
  return received;
}

constexpr std::size_t kBytes = 2 << 20;
constexpr double kRate = 4e6;  // bytes a second: 2 MiB take half a second

TEST(ThrottledProxy, ClientsOnATrunkWithRoomEachGetTheirOwnLinksRate) {
  const std::vector<Received> got = ReceiveAtOnce(4, kBytes, 0, kRate, 100 * kRate);
  for (const Received& r : got) {
    ASSERT_EQ(r.bytes, kBytes);
    const double rate = static_cast<double>(r.bytes) / r.all_s;
    EXPECT_LE(rate, 1.1 * kRate);
    // Not a quarter of it, as when a client waited for the others' links.
    EXPECT_GE(rate, 0.5 * kRate);
  }
}

TEST(ThrottledProxy, ClientsShareATrunkNarrowerThanTheirLinks) {
  const std::vector<Received> got = ReceiveAtOnce(2, kBytes, 0, kRate, kRate);
  double slowest = 0;
  for (const Received& r : got) {
    ASSERT_EQ(r.bytes, kBytes);
    slowest = std::max(slowest, r.all_s);
    EXPECT_GE(static_cast<double>(r.bytes) / r.all_s, 0.3 * kRate);  // each its share
  }
  EXPECT_LE(static_cast<double>(2 * kBytes) / slowest, 1.1 * kRate);  // together no more than the trunk
}

TEST(ThrottledProxy, BytesArriveHalfTheRoundTripLate) {
  const std::vector<Received> got = ReceiveAtOnce(1, 1000, 0.2, 0, 0);
  ASSERT_EQ(got[0].bytes, 1000u);
  EXPECT_GE(got[0].first_s, 0.1);
  EXPECT_LT(got[0].first_s, 2.0);
}

}  // namespace
}  // namespace octocosm
