#pragma once
/// @file
/// Conversions between the generated DDS types and the daemon's own types, in
/// one place for the daemon, the tools and the fuzz target.

#include <cstdio>
#include <span>
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
  t.mode = static_cast<uint8_t>(r.mode);
  t.state = static_cast<uint8_t>(r.state);
  t.fault = static_cast<uint8_t>(r.fault);
  t.high_voltage = r.high_voltage;
  t.target = static_cast<uint8_t>(r.target);
  t.chunk_seq = r.chunk_seq;
  t.stamp_ns = r.stamp_ns;
  return t;
}

/// Received Telemetry as a loop record (the inverse of to_telemetry).
inline daemon::CycleRecord to_cycle_record(const pvcgel_v1_Telemetry& t) noexcept {
  daemon::CycleRecord r;
  r.seq = t.seq;
  r.t_s = t.t_s;
  r.r_um = t.r_um;
  r.y_um = t.y_um;
  r.u_V = t.u_V;
  r.e_um = t.e_um;
  r.d_hat = t.d_hat;
  r.latency_us = t.latency_us;
  r.mode = static_cast<control::ControllerMode>(t.mode);
  r.state = static_cast<daemon::LoopState>(t.state);
  r.fault = static_cast<daemon::FaultReason>(t.fault);
  r.high_voltage = t.high_voltage;
  r.target = static_cast<daemon::LoopTarget>(t.target);
  r.chunk_seq = t.chunk_seq;
  r.stamp_ns = t.stamp_ns;
  return r;
}

}  // namespace pvcgel::dds
