#pragma once
/// @file
/// A DDS client of one rig: finds its daemon, sends commands and trajectories
/// and waits for the replies, reads Status and Telemetry. Used by the `pvcgel`
/// client subcommands (and by `ident --rig`).

#include <CLI/CLI.hpp>

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "daemon/dds/dds_participant.hpp"
#include "daemon/input_validation.hpp"
#include "daemon/loop_state.hpp"
#include "pvcgel_v1.h"

namespace pvcgel::tools {

/// Where the rig is: the options every client subcommand takes.
struct ClientOptions {
  std::string rig = "rig1";
  int domain = 0;
  /// Cyclone DDS XML; default from $PVCGEL_DDS_CONFIG.
  std::string dds_config;
  /// How long to look for the daemon and to wait for replies (s).
  double wait_s = 5.0;
};

/// Adds --rig, --domain, --dds-config, --wait to a subcommand.
void add_client_options(CLI::App& cmd, ClientOptions& o);

/// Joins `o.domain` with `o.dds_config` (required: the default configuration
/// would discover on every interface). @throws std::runtime_error saying what to pass.
dds::Entity make_client_participant(const ClientOptions& o);

/// The loop state and fault a received Status reports.
/// @throws std::runtime_error naming the field and the value when it is not one this client knows.
daemon::LoopState state_of(const pvcgel_v1_Status& s);
daemon::FaultReason fault_of(const pvcgel_v1_Status& s);

/// The daemon's answer to one command or chunk.
struct Reply {
  bool accepted = false;
  daemon::RejectReason reason = daemon::RejectReason::accepted;
  std::string detail;
};

/// Thrown when no daemon answers for the rig (none at all, or only other rigs).
class NoDaemon : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The error for a rig that did not show up within `wait_s`: "no daemon found
/// within N s on domain D ..." when nothing was seen, else "rig 'X' unknown;
/// rigs seen: ...". Shared by every client that looks for a daemon.
/// `also_needs` names a further daemon setting the caller depends on (e.g. " and reliable_telemetry = true").
NoDaemon no_daemon_error(const std::string& rig, int domain, double wait_s, const std::vector<std::string>& rigs_seen,
                         const std::string& also_needs = "");

/// Thrown when the daemon refused a command or chunk; what() names the reason.
class Rejected : public std::runtime_error {
 public:
  Rejected(const std::string& what, Reply r) : std::runtime_error(what), reply(std::move(r)) {}
  Reply reply;
};

/// One client connection to one rig.
class DdsClient final {
 public:
  /// Joins DDS (with `o.dds_config`, required) and creates every endpoint.
  /// @param telemetry  also read Telemetry (best-effort unless `reliable_telemetry`)
  explicit DdsClient(const ClientOptions& o, bool telemetry = false, bool reliable_telemetry = false);

  /// Wait for the rig's Status, then until the daemon's readers and writers
  /// have matched ours. @throws NoDaemon (see no_daemon_error).
  const pvcgel_v1_Status& connect();
  /// A Status published after this client matched the daemon (waits up to 1.5 s).
  const pvcgel_v1_Status& fresh_status();
  /// Wait (up to `timeout_s`) for a Status for which `done` holds, e.g. the
  /// state a command leads to; returns the latest Status either way.
  const pvcgel_v1_Status& wait_status(const std::function<bool(const pvcgel_v1_Status&)>& done, double timeout_s);
  /// Latest Status of the rig (call connect() first); refreshed by every wait.
  const pvcgel_v1_Status& status();
  /// Send a command and wait for its reply. @throws Rejected, std::runtime_error (no reply).
  Reply command(daemon::CommandKind kind, std::uint8_t argument = 0, bool throw_on_reject = true);
  /// Send a trajectory (rig_id, client_id, chunk_seq and publish time are
  /// filled in) and wait for its reply. @throws Rejected, std::runtime_error.
  Reply send(pvcgel_v1_Trajectory& t, bool throw_on_reject = true);
  /// Publish without waiting (for flood tests): returns the seq used (`seq` 0:
  /// the next one; another value republishes, as a resend does).
  std::uint64_t publish_command(daemon::CommandKind kind, std::uint8_t argument, std::uint64_t seq = 0);
  std::uint64_t publish_trajectory(pvcgel_v1_Trajectory& t);
  /// Take every reply that arrived (for flood tests).
  std::vector<pvcgel_v1_CommandReply> take_replies();
  /// Take Telemetry samples of this rig that arrived (needs `telemetry`).
  std::vector<pvcgel_v1_Telemetry> take_telemetry(int max = 1024);
  [[nodiscard]] const std::string& client_id() const noexcept { return client_id_; }
  [[nodiscard]] const ClientOptions& options() const noexcept { return opt_; }

 private:
  Reply wait_reply(std::uint64_t seq, bool is_trajectory, const char* what, bool throw_on_reject,
                   const std::function<void()>& resend);
  void poll_status();
  void ensure_writers();
  bool matched_daemon(dds_entity_t endpoint, bool is_writer);

  ClientOptions opt_;
  std::string client_id_;
  std::uint64_t next_seq_;
  dds::Entity participant_, telemetry_topic_, trajectory_topic_, command_topic_, reply_topic_, status_topic_;
  dds::Entity telemetry_reader_, trajectory_writer_, command_writer_, reply_reader_, status_reader_;
  std::optional<pvcgel_v1_Status> status_;
  dds_guid_t daemon_participant_{};
  std::vector<std::string> other_rigs_;
  bool duplicate_rig_ = false;
  std::vector<pvcgel_v1_CommandReply> stray_replies_;
};

}  // namespace pvcgel::tools
