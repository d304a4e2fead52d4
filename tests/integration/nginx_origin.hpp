#pragma once
// A private nginx on loopback serving a scene folder (issue 4: a real http origin in tests and in
// `texstream-bench storage`). The configuration is the project's config/nginx/texstream-origin.conf.in with
// its @...@ fields filled in; nginx runs in the foreground as a child (daemon off, master_process off), with
// its pid, logs and temporary files in a folder of the caller's. The destructor stops it (SIGTERM, then
// SIGKILL after 2 s), so a failing test that returns early still leaves nothing running.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>

#include "../support/patience.hpp"

namespace texstream::test {

inline constexpr const char* kNginxBinary = "/usr/sbin/nginx";

// A port that was free a moment ago (bind to port 0, read it back, close). nginx binds it next; a race with
// another process is possible, so start() retries with a fresh port.
inline uint16_t free_loopback_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return 0;
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  socklen_t len = sizeof a;
  uint16_t port = 0;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0) {
    port = ntohs(a.sin_port);
  }
  ::close(fd);
  return port;
}

inline bool loopback_accepts(uint16_t port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return false;
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(port);
  const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  ::close(fd);
  return ok;
}

class NginxOrigin {
 public:
  // Serves `root` using `conf_template`; `work` holds the filled-in configuration, pid, logs, temporaries.
  // Returns nullptr and sets `error` when nginx is missing or does not come up within 5 s.
  static std::unique_ptr<NginxOrigin> start(const std::filesystem::path& root,
                                            const std::filesystem::path& conf_template,
                                            const std::filesystem::path& work, std::string& error) {
    if (!std::filesystem::exists(kNginxBinary)) {
      error = std::string(kNginxBinary) + " is not installed";
      return nullptr;
    }
    std::ifstream in(conf_template);
    if (!in) {
      error = "cannot read " + conf_template.string();
      return nullptr;
    }
    std::stringstream text;
    text << in.rdbuf();
    std::filesystem::create_directories(work);
    for (int attempt = 0; attempt < 3; ++attempt) {
      const uint16_t port = free_loopback_port();
      std::string conf = text.str();
      replace(conf, "@PREFIX@", std::filesystem::absolute(work).string());
      replace(conf, "@ROOT@", std::filesystem::absolute(root).string());
      replace(conf, "@PORT@", std::to_string(port));
      // As root, nginx would switch its worker to `nobody`; with master_process off there is no worker, but
      // the directive keeps nginx from complaining about a missing user either way.
      replace(conf, "@USER_LINE@", ::geteuid() == 0 ? "user root;" : "");
      const std::filesystem::path conf_path = work / "nginx.conf";
      std::ofstream(conf_path) << conf;
      auto origin = std::unique_ptr<NginxOrigin>(new NginxOrigin());
      origin->port_ = port;
      origin->log_ = work / "error.log";
      origin->work_ = work;
      origin->conf_path_ = conf_path;
      if (origin->launch()) return origin;
      std::ifstream err(work / "nginx.stderr");
      std::stringstream e;
      e << err.rdbuf();
      error = "nginx did not start on port " + std::to_string(port) + ": " + e.str();
    }
    return nullptr;
  }

  ~NginxOrigin() { stop(); }
  NginxOrigin(const NginxOrigin&) = delete;
  NginxOrigin& operator=(const NginxOrigin&) = delete;

  void stop() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGTERM);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(2);
    int status = 0;
    while (::waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > deadline) {
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    pid_ = 0;
  }

  // Starts it again on the same port after stop() (an origin that was down and comes back). False if it did
  // not come up within 5 s.
  bool restart() {
    stop();
    return launch();
  }

  uint16_t port() const { return port_; }
  // "http://127.0.0.1:<port>/<location>" (location: unlimited, mb10, t1, isdn, fail500, fail503, missing).
  std::string url(const std::string& location) const {
    return "http://127.0.0.1:" + std::to_string(port_) + "/" + location;
  }
  const std::filesystem::path& error_log() const { return log_; }

 private:
  NginxOrigin() = default;
  // Runs nginx on port_ with conf_path_ and waits until it accepts (5 s); false if it exited or never did.
  bool launch() {
    // Everything the child needs is built before fork(): after it, only async-signal-safe calls.
    const std::string prefix = std::filesystem::absolute(work_).string() + "/";
    const std::string out = (work_ / "nginx.stderr").string();
    const std::string conf = conf_path_.string();
    pid_ = ::fork();
    if (pid_ == 0) {
      const int fd = ::open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd >= 0) ::dup2(fd, 2);
      ::execl(kNginxBinary, kNginxBinary, "-p", prefix.c_str(), "-c", conf.c_str(), static_cast<char*>(nullptr));
      ::_exit(127);
    }
    const auto deadline = std::chrono::steady_clock::now() + kHangAfter;
    while (std::chrono::steady_clock::now() < deadline) {
      if (loopback_accepts(port_)) return true;
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = 0;  // exited (port taken?)
        return false;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  }
  static void replace(std::string& s, const std::string& from, const std::string& to) {
    for (size_t at = s.find(from); at != std::string::npos; at = s.find(from, at + to.size()))
      s.replace(at, from.size(), to);
  }
  pid_t pid_ = 0;
  uint16_t port_ = 0;
  std::filesystem::path log_;
  std::filesystem::path work_;
  std::filesystem::path conf_path_;
};

}  // namespace texstream::test
