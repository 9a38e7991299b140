#pragma once
/// @file
/// Conversions between the generated DDS types and the daemon's own types, in
/// one place for the daemon, the tools and the fuzz target.

#include <cstdio>
#include <span>
#include <stdexcept>
#include <string>

#include "daemon/control_loop.hpp"
#include "daemon/input_validation.hpp"
#include "pvcgel_v1.h"

namespace pvcgel::dds {

/// Copies `src` into a bounded IDL string (char[N]), truncating and terminating.
template <std::size_t N>
void copy_bounded(char (&dst)[N], const std::string& src) noexcept {
  std::snprintf(dst, N, "%s", src.c_str());
}

/// The enumerator a received octet stands for, for clients reading the
/// daemon's messages. @throws std::runtime_error naming the field, the value
/// and the values known here (a daemon of another version, or a corrupt
/// message): an unknown value is an error, never a cast or an array index.
template <typename E>
E checked_from_wire(std::uint8_t value, const char* field) {
  if (const auto e = from_wire<E>(value)) return *e;
  const auto& table = names_of(E{});
  std::string known;
  for (std::size_t i = 0; i < table.size(); ++i)
    known += (i ? ", " : "") + std::to_string(to_wire(table.first()) + i) + " " + std::string(table.names()[i]);
  throw std::runtime_error(std::string(field) + " = " + std::to_string(value) + " is not a value this program knows (" +
                           known + "): a daemon of another version, or a corrupt message");
}

/// A received Trajectory as the validator sees it (views into `t`, which must outlive the result).
inline daemon::TrajectoryMessage to_trajectory_message(const pvcgel_v1_Trajectory& t) noexcept {
  daemon::TrajectoryMessage m;
  m.rig_id = t.rig_id;
  m.client_id = t.client_id;
  m.chunk_seq = t.chunk_seq;
  m.target = t.target;
  m.kind = t.kind;
  m.timing = t.timing;
  m.start_time_s = t.start_time_s;
  m.period_s = t.period_s;
  m.duration_s = t.duration_s;
  m.blend_s = t.blend_s;
  m.values = std::span<const double>(t.values._buffer, t.values._length);
  return m;
}

/// A loop record as Telemetry of rig `rig_id`.
inline pvcgel_v1_Telemetry to_telemetry(const daemon::CycleRecord& r, const std::string& rig_id) noexcept {
  pvcgel_v1_Telemetry t{};
  copy_bounded(t.rig_id, rig_id);
  t.seq = r.seq;
  t.t_s = r.t_s;
  t.r_um = r.r_um;
  t.y_um = r.y_um;
  t.u_V = r.u_V;
  t.e_um = r.e_um;
  t.d_hat = r.d_hat;
  t.latency_us = r.latency_us;
  t.mode = to_wire(r.mode);
  t.state = to_wire(r.state);
  t.fault = to_wire(r.fault);
  t.high_voltage = r.high_voltage;
  t.target = to_wire(r.target);
  t.chunk_seq = r.chunk_seq;
  t.stamp_ns = r.stamp_ns;
  return t;
}

/// Received Telemetry as a loop record (the inverse of to_telemetry).
/// @throws std::runtime_error naming the field of an unknown mode, state, fault or target.
inline daemon::CycleRecord to_cycle_record(const pvcgel_v1_Telemetry& t) {
  daemon::CycleRecord r;
  r.seq = t.seq;
  r.t_s = t.t_s;
  r.r_um = t.r_um;
  r.y_um = t.y_um;
  r.u_V = t.u_V;
  r.e_um = t.e_um;
  r.d_hat = t.d_hat;
  r.latency_us = t.latency_us;
  r.mode = checked_from_wire<control::ControllerMode>(t.mode, "Telemetry.mode");
  r.state = checked_from_wire<daemon::LoopState>(t.state, "Telemetry.state");
  r.fault = checked_from_wire<daemon::FaultReason>(t.fault, "Telemetry.fault");
  r.high_voltage = t.high_voltage;
  r.target = checked_from_wire<daemon::LoopTarget>(t.target, "Telemetry.target");
  r.chunk_seq = t.chunk_seq;
  r.stamp_ns = t.stamp_ns;
  return r;
}

}  // namespace pvcgel::dds
