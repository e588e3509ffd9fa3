#include "bench/throttled_proxy.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <string>

#include "base/error.h"

namespace octocosm {
namespace {

using Clock = std::chrono::steady_clock;

bool SendAll(int fd, const std::vector<char>& bytes) {
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t sent = ::send(fd, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
    if (sent <= 0) return false;
    done += static_cast<std::size_t>(sent);
  }
  return true;
}

// Chunks in flight on one direction of a connection, each with the time it arrives.
struct DelayLine {
  std::mutex mutex;
  std::condition_variable changed;
  std::deque<std::pair<Clock::time_point, std::vector<char>>> chunks;
  bool closed = false;
};

}  // namespace

sockaddr_in LoopbackAddress(int port) {
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  address.sin_port = htons(static_cast<std::uint16_t>(port));
  return address;
}

ThrottledProxy::ThrottledProxy(int server_port, double round_trip_s, double client_bytes_per_second,
                               std::shared_ptr<PacedLink> trunk)
    : server_port_(server_port),
      one_way_delay_s_(round_trip_s / 2),
      client_link_(client_bytes_per_second),
      trunk_(std::move(trunk)) {
  listener_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in address = LoopbackAddress(0);
  if (listener_ < 0 || ::bind(listener_, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0 ||
      ::listen(listener_, 128) != 0) {
    throw Error::Io("throttled proxy", "cannot listen on 127.0.0.1");
  }
  socklen_t length = sizeof address;
  ::getsockname(listener_, reinterpret_cast<sockaddr*>(&address), &length);
  port_ = ntohs(address.sin_port);
  acceptor_ = std::thread([this] { AcceptLoop(); });
}

ThrottledProxy::~ThrottledProxy() {
  stopping_ = true;
  ::shutdown(listener_, SHUT_RDWR);
  acceptor_.join();
  std::vector<std::thread> threads;
  {
    std::lock_guard<std::mutex> lock(threads_mutex_);
    for (int fd : sockets_) ::shutdown(fd, SHUT_RDWR);
    threads.swap(threads_);
  }
  for (std::thread& t : threads) t.join();
  for (int fd : sockets_) ::close(fd);
  ::close(listener_);
}

// Each connection to the server is made on the connection's own thread, so
// that a slow connect (a full backlog waits for a SYN to be sent again, 1 s
// and then 3 s) holds up that connection alone, not every accept after it.
void ThrottledProxy::AcceptLoop() {
  while (!stopping_) {
    const int client = ::accept4(listener_, nullptr, nullptr, SOCK_CLOEXEC);
    if (client < 0) {
      if (stopping_) return;
      continue;
    }
    std::lock_guard<std::mutex> lock(threads_mutex_);
    sockets_.push_back(client);
    threads_.emplace_back([this, client] { Relay(client); });
  }
}

void ThrottledProxy::Relay(int client) {
  const int server = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in address = LoopbackAddress(server_port_);
  if (server < 0 || ::connect(server, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0) {
    if (server >= 0) ::close(server);
    ::shutdown(client, SHUT_RDWR);  // closed with the others when the proxy goes
    return;
  }
  {
    // The destructor shuts down every socket it finds here; one made after
    // it looked is not relayed.
    std::lock_guard<std::mutex> lock(threads_mutex_);
    if (stopping_) {
      ::close(server);
      return;
    }
    sockets_.push_back(server);
  }
  const int yes = 1;
  ::setsockopt(client, IPPROTO_TCP, TCP_NODELAY, &yes, sizeof yes);
  ::setsockopt(server, IPPROTO_TCP, TCP_NODELAY, &yes, sizeof yes);
  std::thread requests([this, client, server] { Pump(client, server, false); });
  Pump(server, client, true);
  requests.join();
}

Clock::time_point ThrottledProxy::Pace(std::size_t bytes) {
  const auto occupy = [bytes](const PacedLink& link, Clock::time_point start) {
    if (link.bytes_per_second_ <= 0) return start;
    return start + std::chrono::duration_cast<Clock::duration>(
                       std::chrono::duration<double>(static_cast<double>(bytes) / link.bytes_per_second_));
  };
  // Flow control: a chunk read from the server is booked only once the
  // client's link has no more than this chunk's time left to send. Until
  // then this connection reads nothing more, so TCP holds the server back,
  // and no client books the trunk ahead of what its own link can carry.
  Clock::time_point drained;
  {
    std::lock_guard<std::mutex> lock(client_link_.mutex_);
    drained = client_link_.free_at_ - (occupy(client_link_, Clock::now()) - Clock::now());
  }
  std::this_thread::sleep_until(drained);
  Clock::time_point through_trunk;
  {
    std::lock_guard<std::mutex> lock(trunk_->mutex_);
    const Clock::time_point start = std::max(Clock::now(), trunk_->free_at_);
    trunk_->free_at_ = occupy(*trunk_, start);
    through_trunk = trunk_->free_at_;
  }
  std::lock_guard<std::mutex> lock(client_link_.mutex_);
  client_link_.free_at_ = occupy(client_link_, std::max(through_trunk, client_link_.free_at_));
  return client_link_.free_at_;
}

// Reads from `from` and delivers to `to` through a delay line: a reader
// stamps each chunk with its arrival time, a writer sends it then.
void ThrottledProxy::Pump(int from, int to, bool to_client) {
  DelayLine line;
  const auto delay = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(one_way_delay_s_));
  std::thread writer([&] {
    std::unique_lock<std::mutex> lock(line.mutex);
    for (;;) {
      line.changed.wait(lock, [&] { return line.closed || !line.chunks.empty(); });
      if (line.chunks.empty()) break;
      auto [arrival, bytes] = std::move(line.chunks.front());
      line.chunks.pop_front();
      lock.unlock();
      std::this_thread::sleep_until(arrival);
      const bool sent = SendAll(to, bytes);
      if (sent && to_client) bytes_to_client_.fetch_add(bytes.size());
      lock.lock();
      if (!sent) break;
    }
    ::shutdown(to, SHUT_WR);
  });
  // Large reads: each chunk costs a wake-up of the writer and a paced send,
  // and with eight clients on two cores the proxies' CPU is taken from the
  // clients the bench measures (64 KiB chunks cost a third more of it). At
  // 100 MB/s a chunk occupies the link for 2.6 ms, well inside a round trip.
  std::vector<char> buffer(256 * 1024);
  std::string tail;  // the last bytes towards the server, for an end of headers split between reads
  for (;;) {
    const ssize_t got = ::recv(from, buffer.data(), buffer.size(), 0);
    if (got <= 0) break;
    if (!to_client) {
      tail.append(buffer.data(), static_cast<std::size_t>(got));
      for (std::size_t at = tail.find("\r\n\r\n"); at != std::string::npos; at = tail.find("\r\n\r\n")) {
        requests_.fetch_add(1);
        tail.erase(0, at + 4);
      }
      if (tail.size() > 3) tail.erase(0, tail.size() - 3);
    }
    const Clock::time_point left = to_client ? Pace(static_cast<std::size_t>(got)) : Clock::now();
    std::lock_guard<std::mutex> lock(line.mutex);
    line.chunks.emplace_back(left + delay, std::vector<char>(buffer.begin(), buffer.begin() + got));
    line.changed.notify_one();
  }
  {
    std::lock_guard<std::mutex> lock(line.mutex);
    line.closed = true;
    line.changed.notify_one();
  }
  writer.join();
}

}  // namespace octocosm
