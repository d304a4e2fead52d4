#pragma once
// Test helpers that run code in a forked child: checks that need a process of their own (a mount namespace
// with a small tmpfs, a segment owner to SIGKILL). Header-only; included by unit and integration tests as
// "../support/forked_child.hpp".
#include <errno.h>
#include <sched.h>
#include <signal.h>
#include <sys/mount.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <functional>
#include <string>

namespace texstream::test {

// How a forked child ended: its exit code (-1 if a signal ended it) and what it reported.
struct ChildResult {
  int code = -1;
  int signal = 0;
  std::string text;
};

// The exit code a child uses for "cannot run here" (no privileges for a mount namespace): tests skip on it.
inline constexpr int kChildCannotRun = 77;

// Runs `body` in a forked child. The child ends by calling `finish(text, code)`, which reports `text` to the
// parent and exits with `code`; returning from `body` without it is exit code 0 with no text.
inline ChildResult run_in_child(const std::function<void(const std::function<void(const std::string&, int)>&)>& body) {
  int fds[2];
  if (::pipe(fds) != 0) return {-1, 0, std::string("pipe: ") + std::strerror(errno)};
  const pid_t child = ::fork();
  if (child < 0) return {-1, 0, std::string("fork: ") + std::strerror(errno)};
  if (child == 0) {
    ::close(fds[0]);
    const auto finish = [&](const std::string& text, int code) {
      (void)!::write(fds[1], text.data(), text.size());
      ::_exit(code);
    };
    body(finish);
    ::_exit(0);
  }
  ::close(fds[1]);
  ChildResult r;
  char buf[512];
  ssize_t n;
  while ((n = ::read(fds[0], buf, sizeof buf)) > 0) r.text.append(buf, static_cast<size_t>(n));
  ::close(fds[0]);
  int status = 0;
  if (::waitpid(child, &status, 0) != child) return {-1, 0, r.text + " (waitpid failed)"};
  if (WIFEXITED(status)) r.code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) r.signal = WTERMSIG(status);
  return r;
}

// In a child: a mount namespace of its own (private propagation first, or the mount would show on the host)
// and a tmpfs of `size` ("1m", "64k") on `dir`. False, with errno, where that is not permitted (not root).
inline bool mount_private_tmpfs(const std::string& dir, const std::string& size) {
  return ::unshare(CLONE_NEWNS) == 0 && ::mount(nullptr, "/", nullptr, MS_REC | MS_PRIVATE, nullptr) == 0 &&
         ::mount("tmpfs", dir.c_str(), "tmpfs", 0, ("size=" + size).c_str()) == 0;
}

// A forked child that runs `create` (true: it made what the test needs, e.g. a segment) and then sleeps until
// killed. Returns its pid, or -1 if `create` failed (the child is then reaped).
inline pid_t fork_sleeper(const std::function<bool()>& create) {
  int fds[2];
  if (::pipe(fds) != 0) return -1;
  const pid_t child = ::fork();
  if (child < 0) return -1;
  if (child == 0) {
    ::close(fds[0]);
    const char ok = create() ? 1 : 0;
    (void)!::write(fds[1], &ok, 1);
    for (;;) ::pause();  // killed by the test; never returns into gtest
  }
  ::close(fds[1]);
  char ok = 0;
  const bool got = ::read(fds[0], &ok, 1) == 1;
  ::close(fds[0]);
  if (!got || ok != 1) {
    ::kill(child, SIGKILL);
    ::waitpid(child, nullptr, 0);
    return -1;
  }
  return child;
}

}  // namespace texstream::test
