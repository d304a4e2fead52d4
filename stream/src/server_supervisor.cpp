#include "texstream/stream/server_supervisor.hpp"

#include <unistd.h>

#include <spdlog/spdlog.h>

#include "texstream/protocol/liveness.hpp"

namespace texstream::stream {

ServerSupervisor::ServerSupervisor(Segment& segment, std::unique_ptr<ServerProcess> process,
                                   std::chrono::milliseconds heartbeat_timeout)
    : segment_(segment), process_(std::move(process)), heartbeat_timeout_(heartbeat_timeout) {}

ServerSupervisor::~ServerSupervisor() { process_.reset(); }

bool ServerSupervisor::accepting_requests() const {
  if (broken_) return false;
  return process_ ? process_->serving() : true;
}

void ServerSupervisor::spawn_if_due(SteadyTime t) {
  // relaxed: read by the server only after it was spawned (the spawn orders it).
  segment_.renderer_block().server_epoch.v.store(segment_.header().epoch, std::memory_order_relaxed);
  process_->spawn_if_due(t);
}

void ServerSupervisor::supervise(SteadyTime t, bool ring_broken, bool work_waiting, Client& client) {
  if (!process_) {
    if (ring_broken && !broken_) {
      client.protocol_error("a ring position of the external server is impossible; stopping until reset");
      broken_ = true;
      client.server_gone({.why = "ring corrupt", .reset = false});
      return;
    }
    watch_external_server(t, client);
    return;
  }
  if (auto exit = process_->reap(t)) {
    const ServerBlock& sb = segment_.server_block();
    const uint32_t holder = sb.pid.v.load(std::memory_order_acquire);
    const uint64_t holder_start = sb.start_time.v.load(std::memory_order_acquire);
    if (holder != 0 && holder != static_cast<uint32_t>(exit->pid) && holder_start != 0 &&
        process_alive(static_cast<int>(holder), holder_start)) {
      // Our child found the segment held by another server (a standalone texstream-server on this
      // protocol.segment_name) and left. A reset would pull the rings from under that server: it serves this
      // renderer from now on, as with server.spawn = false, and no child is started again.
      spdlog::warn(
          "segment '{}' is served by a standalone texstream-server (pid {}): using it, as with "
          "server.spawn = false; child pid {} {}",
          segment_.name(), holder, exit->pid, exit->how);
      process_.reset();
      return;
    }
    ++server_deaths_;
    // The server writes its pid when it attaches and leaves it there when it detaches; the reset clears it.
    const bool attached = exit->pid > 0 && segment_.server_block().pid.v.load(std::memory_order_relaxed) ==
                                               static_cast<uint32_t>(exit->pid);
    deaths_before_attach_ = attached ? 0 : deaths_before_attach_ + 1;
    const bool refused = !attached && !exit->killed_by_us && exit->exit_status == kServerExitBadConfig;
    refusals_before_attach_ = refused ? refusals_before_attach_ + 1 : 0;
    last_server_exit_ = "pid " + std::to_string(exit->pid) + " " + exit->how +
                        (exit->killed_by_us ? " after we killed it: " + exit->kill_reason : "");
    // The client charges the quarantine before the reset (which zeroes the words); only now, with the
    // process reaped, are its words in the segment ours to reset.
    client.server_gone({.why = last_server_exit_,
                        .crash_signal = exit->killed_by_us ? 0 : exit->term_signal,
                        .hung = exit->hung,
                        .reset = true});
  }
  if (process_->serving()) {
    if (ring_broken) {
      client.protocol_error("a ring position is impossible");
      process_->kill("it corrupted a ring position");
    } else {
      const ServerBlock& sb = segment_.server_block();
      process_->watch_heartbeat(sb.heartbeat.v.load(std::memory_order_relaxed),
                                sb.attached.v.load(std::memory_order_relaxed) == 1, work_waiting, heartbeat_timeout_,
                                t);
    }
  }
  if (!process_->has_child()) spawn_if_due(t);
}

void ServerSupervisor::restart(const std::string& why, Client& client) {
  if (process_) {
    process_->kill(why);  // the next supervise() reaps it, marks requests lost, resets and respawns
    return;
  }
  client.server_gone({.why = why, .reset = true});
  broken_ = false;
}

void ServerSupervisor::watch_external_server(SteadyTime t, Client& client) {
  // A standalone server (server.spawn = false) is no child of ours: its death is told by its identity in the
  // ServerBlock, pid + start time, looked at every kExternalServerCheck. Then its requests are lost and the
  // block and rings are reset, as after a spawned server's death, so that the next standalone server (its
  // supervisor restarts it, or a person does) can claim the segment: a server claims it only while the pid
  // word is 0 (Server::run). The in-process server is this process: never dead here.
  if (t < next_external_check_) return;
  next_external_check_ = t + kExternalServerCheck;
  const ServerBlock& sb = segment_.server_block();
  const uint32_t pid = sb.pid.v.load(std::memory_order_acquire);
  // start_time 0: a server between its claim of the pid word and publishing its start time.
  const uint64_t start_time = sb.start_time.v.load(std::memory_order_acquire);
  if (const uint32_t refused = sb.refused_by.v.load(std::memory_order_acquire);
      pid == 0 && refused != 0 && standalone_refused_by_ == 0) {
    standalone_refused_by_ = refused;
    last_server_exit_ = "standalone texstream-server pid " + std::to_string(refused) + " refused segment '" +
                        segment_.name() +
                        "': it reads another scene than this renderer (its texture table differs; its log names "
                        "both tables)";
  }
  if (pid == 0) {
    // Nobody serves the segment yet: say so once after a while (a preload would otherwise wait silently).
    if (external_unserved_since_ == SteadyTime{}) external_unserved_since_ = t;
    if (!external_unserved_told_ && t - external_unserved_since_ >= kExternalUnservedWarning) {
      spdlog::warn(
          "no texstream-server has attached to segment '{}' for {} s (server.spawn = false): start one "
          "with texstream-server --segment {} --scene DIR",
          segment_.name(), std::chrono::duration_cast<std::chrono::seconds>(kExternalUnservedWarning).count(),
          segment_.name());
      external_unserved_told_ = true;
    }
  } else {
    external_unserved_since_ = SteadyTime{};
    external_unserved_told_ = false;
  }
  if (pid == 0 || start_time == 0 || pid == static_cast<uint32_t>(::getpid())) return;
  if (process_alive(static_cast<int>(pid), start_time)) return;
  ++server_deaths_;
  last_server_exit_ = "standalone texstream-server pid " + std::to_string(pid) + " is gone";
  spdlog::warn("{}: its requests are sent again once another server attaches", last_server_exit_);
  client.server_gone({.why = last_server_exit_, .reset = true});
}

std::string ServerSupervisor::unattached_reason() const {
  if (std::as_const(segment_).server_block().attached.v.load(std::memory_order_acquire) == 1) return {};
  std::string why = "no texstream-server is attached to segment '" + segment_.name() + "'";
  if (!process_) {
    why += " (server.spawn = false): start one with texstream-server --segment " + segment_.name() + " --scene DIR";
  }
  return why;
}

}  // namespace texstream::stream
