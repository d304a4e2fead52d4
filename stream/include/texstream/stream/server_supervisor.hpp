#pragma once
// The renderer's supervision of whoever serves its segment: a spawned texstream-server (ServerProcess:
// start, reap, heartbeat watchdog, restart with back-off, colormap-only) or, with server.spawn = false, a
// standalone server told dead by its identity in the ServerBlock. It decides when a server is gone; what
// that means for the requests in flight is the client's (ServerSupervisor::Client::server_gone).
//
// Single-threaded: the renderer's frame thread (through StreamClient) makes every call.
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include "texstream/protocol/segment.hpp"
#include "texstream/stream/server_process.hpp"

namespace texstream::stream {

class ServerSupervisor {
 public:
  // How a server ended, for the client and its quarantine.
  struct Death {
    std::string why;       // for the log ("pid 12 exited with status 2 ...")
    int crash_signal = 0;  // the signal that ended a spawned server we did not kill; 0 otherwise
    bool hung = false;     // we killed it because its heartbeat stalled while it was serving
    bool reset = true;     // the segment is to be reset (false: an external server broke a ring)
  };
  // What the supervisor asks of the client it serves; called from within supervise() and restart().
  class Client {
   public:
    virtual ~Client() = default;
    // The server is gone: before any reset (its words are still there) say who to charge (`death`), then
    // lose what was in flight; when death.reset, reset the segment and take fresh ring ends.
    virtual void server_gone(const Death& death) = 0;
    virtual void protocol_error(const std::string& what) = 0;
  };

  // `process`: the spawned server (its first spawn is due), or null when someone else serves the segment.
  ServerSupervisor(Segment& segment, std::unique_ptr<ServerProcess> process,
                   std::chrono::milliseconds heartbeat_timeout);
  ~ServerSupervisor();  // kills and reaps a spawned server
  ServerSupervisor(const ServerSupervisor&) = delete;
  ServerSupervisor& operator=(const ServerSupervisor&) = delete;

  // Spawns the first server (a spawned one: at once; its back-off starts with its first death).
  void start(SteadyTime t) {
    if (process_) spawn_if_due(t);
  }
  // Once per poll (and at once after a ring error): reap, watchdog, restart, or watch the external server.
  // `ring_broken`: a ring position published by the server is impossible; `work_waiting`: requests in flight.
  void supervise(SteadyTime t, bool ring_broken, bool work_waiting, Client& client);
  // Kills the spawned server as if it had hung (the next supervise() reaps and restarts it). Without a
  // child: the server is gone now (the caller guarantees the external server has let go of the segment).
  void restart(const std::string& why, Client& client);

  bool accepting_requests() const;
  bool spawned() const { return process_ != nullptr; }
  int server_pid() const { return process_ ? process_->pid() : -1; }
  const std::string& last_server_exit() const { return last_server_exit_; }
  // Empty if a server is attached to the segment now; else why not, for an error that has to say it.
  std::string unattached_reason() const;

  // StreamStats' supervision counters (stream_client.hpp says what each means).
  uint64_t server_deaths() const { return server_deaths_; }
  uint64_t server_deaths_before_attach() const { return deaths_before_attach_; }
  uint64_t server_refusals_before_attach() const { return refusals_before_attach_; }
  uint32_t standalone_refused_by() const { return standalone_refused_by_; }
  uint64_t server_crashes() const { return process_ ? process_->crashes() : 0; }
  uint64_t server_restarts() const { return process_ && process_->spawns() > 0 ? process_->spawns() - 1 : 0; }
  const ServerProcess* process() const { return process_.get(); }
  bool broken() const { return broken_; }

 private:
  void watch_external_server(SteadyTime t, Client& client);
  void spawn_if_due(SteadyTime t);

  Segment& segment_;
  std::unique_ptr<ServerProcess> process_;  // null when spawn_server is false
  std::chrono::milliseconds heartbeat_timeout_;
  bool broken_ = false;  // external server broke a ring
  std::string last_server_exit_;
  uint64_t server_deaths_ = 0;
  uint64_t deaths_before_attach_ = 0;
  uint64_t refusals_before_attach_ = 0;
  uint32_t standalone_refused_by_ = 0;
  // server.spawn = false: when watch_external_server() looks at the standalone server's identity next.
  static constexpr std::chrono::milliseconds kExternalServerCheck{100};
  SteadyTime next_external_check_{};
  static constexpr std::chrono::seconds kExternalUnservedWarning{3};
  SteadyTime external_unserved_since_{};  // since when no server has held the segment ({}: one does)
  bool external_unserved_told_ = false;
};

}  // namespace texstream::stream
