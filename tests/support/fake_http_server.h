// A scripted HTTP/1.1 server on 127.0.0.1 for the HTTP reader's tests: it
// serves files from memory with range requests and keep-alive, and each
// request can be answered another way (a status, the whole file, a short or
// wrong range, a changed file, a cut connection, silence) to check that
// every fault becomes the right error.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace octocosm::testing_support {

class FakeHttpServer {
 public:
  struct Request {
    std::string path;
    std::optional<std::pair<std::uint64_t, std::uint64_t>> range;  // first, last (inclusive)
    int number = 0;  // 0 for the server's first request
  };
  // How to answer; defaults serve the file as a static server does.
  enum class Answer { kNormal, kIgnoreRange, kStatus, kCutShort, kSilence, kWrongRange, kChangedEtag };
  struct Behaviour {
    Answer answer = Answer::kNormal;
    int status = 0;  // for kStatus
  };
  // Chooses the answer to each request (called on the server's threads).
  using Script = std::function<Behaviour(const Request&)>;

  FakeHttpServer() {
    listener_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    int yes = 1;
    ::setsockopt(listener_, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    address.sin_port = 0;
    ::bind(listener_, reinterpret_cast<sockaddr*>(&address), sizeof address);
    ::listen(listener_, 64);
    socklen_t length = sizeof address;
    ::getsockname(listener_, reinterpret_cast<sockaddr*>(&address), &length);
    port_ = ntohs(address.sin_port);
    acceptor_ = std::thread([this] { AcceptLoop(); });
  }

  ~FakeHttpServer() {
    stopping_ = true;
    ::shutdown(listener_, SHUT_RDWR);
    acceptor_.join();
    std::vector<std::thread> connections;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (int fd : open_fds_) ::shutdown(fd, SHUT_RDWR);
      connections.swap(connections_);
    }
    for (std::thread& t : connections) t.join();
    ::close(listener_);
  }

  FakeHttpServer(const FakeHttpServer&) = delete;
  FakeHttpServer& operator=(const FakeHttpServer&) = delete;

  void Put(const std::string& path, std::string contents) {
    std::lock_guard<std::mutex> lock(mutex_);
    files_[path] = std::move(contents);
  }
  void SetScript(Script script) {
    std::lock_guard<std::mutex> lock(mutex_);
    script_ = std::move(script);
  }
  std::string Url(const std::string& path) const { return "http://127.0.0.1:" + std::to_string(port_) + path; }
  int requests() const { return requests_.load(); }
  int connections() const { return connections_accepted_.load(); }

 private:
  void AcceptLoop() {
    while (!stopping_) {
      const int fd = ::accept4(listener_, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd < 0) {
        if (stopping_) return;
        continue;
      }
      connections_accepted_.fetch_add(1);
      std::lock_guard<std::mutex> lock(mutex_);
      open_fds_.push_back(fd);
      connections_.emplace_back([this, fd] { Serve(fd); });
    }
  }

  // Reads one request head; false when the connection ends.
  static bool ReadHead(int fd, std::string& buffer, std::string& head) {
    for (;;) {
      const std::size_t end = buffer.find("\r\n\r\n");
      if (end != std::string::npos) {
        head = buffer.substr(0, end);
        buffer.erase(0, end + 4);
        return true;
      }
      char chunk[4096];
      const ssize_t got = ::recv(fd, chunk, sizeof chunk, 0);
      if (got <= 0) return false;
      buffer.append(chunk, static_cast<std::size_t>(got));
    }
  }

  static void SendAll(int fd, const std::string& bytes) {
    std::size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t sent = ::send(fd, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
      if (sent <= 0) return;
      done += static_cast<std::size_t>(sent);
    }
  }

  void Serve(int fd) {
    std::string buffer, head;
    while (!stopping_ && ReadHead(fd, buffer, head)) {
      Request request;
      std::istringstream lines(head);
      std::string method, version;
      lines >> method >> request.path >> version;
      std::string line;
      while (std::getline(lines, line)) {
        if (line.rfind("Range: bytes=", 0) == 0) {
          const std::string spec = line.substr(13);
          const std::size_t dash = spec.find('-');
          request.range = std::make_pair(std::stoull(spec.substr(0, dash)), std::stoull(spec.substr(dash + 1)));
        }
      }
      request.number = requests_.fetch_add(1);
      Behaviour behaviour;
      std::optional<std::string> file;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (script_) behaviour = script_(request);
        auto it = files_.find(request.path);
        if (it != files_.end()) file = it->second;
      }
      if (!Respond(fd, request, behaviour, file)) break;
    }
    ::shutdown(fd, SHUT_RDWR);
    ::close(fd);
    std::lock_guard<std::mutex> lock(mutex_);
    std::erase(open_fds_, fd);
  }

  // Sends the answer; false to end the connection.
  bool Respond(int fd, const Request& request, const Behaviour& behaviour, const std::optional<std::string>& file) {
    const auto reply = [&](int status, const std::string& headers, const std::string& body) {
      SendAll(fd, "HTTP/1.1 " + std::to_string(status) + " X\r\nContent-Length: " + std::to_string(body.size()) +
                      "\r\n" + headers + "\r\n" + body);
    };
    switch (behaviour.answer) {
      case Answer::kStatus:
        reply(behaviour.status, "", "status " + std::to_string(behaviour.status));
        return true;
      case Answer::kSilence:
        while (!stopping_) std::this_thread::sleep_for(std::chrono::milliseconds(10));
        return false;
      default:
        break;
    }
    if (!file) {
      reply(404, "", "not found");
      return true;
    }
    const std::string etag =
        "ETag: \"" + std::to_string(file->size()) + (behaviour.answer == Answer::kChangedEtag ? "-new" : "") + "\"\r\n";
    if (!request.range || behaviour.answer == Answer::kIgnoreRange) {
      reply(200, etag, *file);
      return true;
    }
    std::uint64_t first = request.range->first;
    std::uint64_t last = std::min<std::uint64_t>(request.range->second, file->size() - 1);
    if (first >= file->size()) {
      reply(416, "Content-Range: bytes */" + std::to_string(file->size()) + "\r\n", "");
      return true;
    }
    if (behaviour.answer == Answer::kWrongRange) first += 1;
    const std::string body = file->substr(first, last - first + 1);
    const std::string headers = etag + "Content-Range: bytes " + std::to_string(first) + "-" + std::to_string(last) +
                                "/" + std::to_string(file->size()) + "\r\n";
    if (behaviour.answer == Answer::kCutShort) {
      SendAll(fd, "HTTP/1.1 206 X\r\nContent-Length: " + std::to_string(body.size()) + "\r\n" + headers + "\r\n" +
                      body.substr(0, body.size() / 2));
      return false;
    }
    reply(206, headers, body);
    return true;
  }

  int listener_ = -1;
  int port_ = 0;
  std::atomic<bool> stopping_{false};
  std::atomic<int> requests_{0};
  std::atomic<int> connections_accepted_{0};
  std::thread acceptor_;
  std::mutex mutex_;
  std::vector<std::thread> connections_;
  std::vector<int> open_fds_;
  std::map<std::string, std::string> files_;
  Script script_;
};

}  // namespace octocosm::testing_support
