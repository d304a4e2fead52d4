#pragma once
// A deliberately broken http origin on loopback, written with plain sockets (issue 4 item 5: failures nginx
// will not produce on demand). It serves files under `root` for GET requests with a "Range: bytes=a-b"
// header, and breaks each answer the way its Mode says:
//   kTruncatedBody      206 with correct headers, then only half the body and the connection closed
//   kWrongContentRange  206 whose Content-Range (and body) start one byte after the asked offset
//   kSlowloris          the status line and headers, then one body byte every 500 ms (a stalled origin)
// One connection at a time, "Connection: close" after each answer. The destructor stops the thread.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

namespace texstream::test {

class FakeHttpOrigin {
 public:
  enum class Mode { kTruncatedBody, kWrongContentRange, kSlowloris };

  FakeHttpOrigin(Mode mode, std::filesystem::path root) : mode_(mode), root_(std::move(root)) {
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    const int one = 1;
    ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t len = sizeof a;
    if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 && ::listen(listen_fd_, 16) == 0 &&
        ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len) == 0) {
      port_ = ntohs(a.sin_port);
    }
    thread_ = std::thread([this] { serve(); });
  }
  ~FakeHttpOrigin() {
    stop_ = true;
    thread_.join();
    ::close(listen_fd_);
  }
  FakeHttpOrigin(const FakeHttpOrigin&) = delete;
  FakeHttpOrigin& operator=(const FakeHttpOrigin&) = delete;

  uint16_t port() const { return port_; }
  std::string url() const { return "http://127.0.0.1:" + std::to_string(port_); }
  uint32_t requests() const { return requests_.load(); }

 private:
  static bool send_all(int fd, const char* p, size_t n) {
    while (n > 0) {
      const ssize_t w = ::send(fd, p, n, MSG_NOSIGNAL);
      if (w <= 0) return false;
      p += w;
      n -= static_cast<size_t>(w);
    }
    return true;
  }

  // Reads the request head (until a blank line) with a poll deadline; empty when the client went away.
  std::string read_head(int fd) {
    std::string head;
    char buf[2048];
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (head.find("\r\n\r\n") == std::string::npos && std::chrono::steady_clock::now() < deadline && !stop_) {
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, 50) <= 0) continue;
      const ssize_t r = ::recv(fd, buf, sizeof buf, 0);
      if (r <= 0) return {};
      head.append(buf, static_cast<size_t>(r));
    }
    return head;
  }

  void answer(int fd, const std::string& head) {
    requests_.fetch_add(1);
    const size_t sp1 = head.find(' '), sp2 = head.find(' ', sp1 + 1);
    const std::string path = head.substr(sp1 + 1, sp2 - sp1 - 1);
    std::ifstream in(root_ / path.substr(1), std::ios::binary);
    std::vector<char> file((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    uint64_t first = 0, last = file.empty() ? 0 : file.size() - 1;
    const size_t r = head.find("Range: bytes=");
    if (r != std::string::npos) std::sscanf(head.c_str() + r + 13, "%lu-%lu", &first, &last);
    if (!in || file.empty() || first >= file.size()) {
      const std::string h = "HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n";
      send_all(fd, h.data(), h.size());
      return;
    }
    last = std::min<uint64_t>(last, file.size() - 1);
    if (mode_ == Mode::kWrongContentRange && last + 1 < file.size()) {
      ++first;  // the answer is shifted by one byte: same length, wrong place
      ++last;
    }
    const uint64_t n = last - first + 1;
    const std::string h = "HTTP/1.1 206 Partial Content\r\nContent-Type: application/octet-stream\r\nContent-Length: " +
                          std::to_string(n) + "\r\nContent-Range: bytes " + std::to_string(first) + "-" +
                          std::to_string(last) + "/" + std::to_string(file.size()) + "\r\nConnection: close\r\n\r\n";
    if (!send_all(fd, h.data(), h.size())) return;
    const char* body = file.data() + first;
    switch (mode_) {
      case Mode::kTruncatedBody:
        send_all(fd, body, n / 2);
        break;
      case Mode::kWrongContentRange:
        send_all(fd, body, n);
        break;
      case Mode::kSlowloris:
        for (uint64_t i = 0; i < n && !stop_; ++i) {
          if (!send_all(fd, body + i, 1)) break;
          for (int t = 0; t < 10 && !stop_; ++t) std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
        break;
    }
  }

  void serve() {
    while (!stop_) {
      pollfd p{listen_fd_, POLLIN, 0};
      if (::poll(&p, 1, 50) <= 0) continue;
      const int fd = ::accept(listen_fd_, nullptr, nullptr);
      if (fd < 0) continue;
      const std::string head = read_head(fd);
      if (!head.empty()) answer(fd, head);
      ::close(fd);
    }
  }

  const Mode mode_;
  const std::filesystem::path root_;
  int listen_fd_ = -1;
  uint16_t port_ = 0;
  std::atomic<bool> stop_{false};
  std::atomic<uint32_t> requests_{0};
  std::thread thread_;
};

}  // namespace texstream::test
