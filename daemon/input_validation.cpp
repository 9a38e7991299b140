#include "daemon/input_validation.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>

#include "control/controller.hpp"

namespace pvcgel::daemon {

namespace {

template <typename... Args>
Verdict reject(RejectReason r, const char* fmt, Args... args) {
  char buf[160];
  std::snprintf(buf, sizeof buf, fmt, args...);
  return {r, buf};
}

struct Range {
  double min, max, max_step, max_slope;
  const char* unit;
};

Range range_for(LoopTarget t, const SetpointLimits& l) {
  return t == LoopTarget::voltage ? Range{l.min_V, l.max_V, l.max_step_V, l.max_slope_V_per_s, "V"}
                                  : Range{l.min_um, l.max_um, l.max_step_um, l.max_slope_um_per_s, "um"};
}

}  // namespace

namespace {

using Kind = SetpointSegment::Kind;

/// The codes, ids and numbers every message must have right, whatever its kind.
Verdict check_fields(const TrajectoryMessage& m, const LoopView& loop) {
  if (m.client_id.empty()) return reject(RejectReason::malformed, "client_id is empty");
  if (m.chunk_seq == 0) return reject(RejectReason::malformed, "chunk_seq must be nonzero");
  const auto target = from_wire<LoopTarget>(m.target);
  if (!target) return reject(RejectReason::malformed, "target %u is not 0 (displacement) or 1 (voltage)", m.target);
  if (!from_wire<Kind>(m.kind))
    return reject(RejectReason::malformed, "kind %u is not 0..4 (samples, hold, ramp, sine, multisine)", m.kind);
  if (m.timing > 1) return reject(RejectReason::malformed, "timing %u is not 0 (replace) or 1 (append)", m.timing);
  if (*target != loop.target)
    return reject(RejectReason::target_mismatch, "setpoints for %s but the loop is in %s mode (send set_target first)",
                  to_string(*target).data(), to_string(loop.target).data());
  for (const double x : {m.start_time_s, m.period_s, m.duration_s, m.blend_s})
    if (!std::isfinite(x)) return reject(RejectReason::not_finite, "a time field is %f", x);
  for (std::size_t i = 0; i < m.values.size(); ++i)
    if (!std::isfinite(m.values[i])) return reject(RejectReason::not_finite, "values[%zu] is %f", i, m.values[i]);
  if (m.blend_s < 0.0 || m.blend_s > 60.0) return reject(RejectReason::bad_duration, "blend_s %.6g is not in 0..60 s", m.blend_s);
  if (m.duration_s < 0.0) return reject(RejectReason::bad_duration, "duration_s %.6g is negative", m.duration_s);
  return {};
}

/// An absolute start must lie in the loop's window; appending must leave room ahead.
/// Times print with %.10g: a start time of 1e300 s is named in a dozen characters, not 300 digits.
Verdict check_timing(const TrajectoryMessage& m, const SetpointLimits& limits, const LoopView& loop) {
  const bool at = m.timing == 0 && m.start_time_s >= 0.0;
  if (at && m.start_time_s < loop.now_s - limits.past_tolerance_s)
    return reject(RejectReason::in_the_past, "start_time_s %.10g is before the loop time %.10g", m.start_time_s, loop.now_s);
  if (at && m.start_time_s > loop.now_s + limits.max_lead_s)
    return reject(RejectReason::too_far_ahead, "start_time_s %.10g is more than %.3g s after the loop time %.10g",
                  m.start_time_s, limits.max_lead_s, loop.now_s);
  if (m.timing == 1 && loop.queued_until_s > loop.now_s + limits.max_lead_s)
    return reject(RejectReason::busy, "setpoints are already queued up to %.10g s, more than %.3g s ahead of %.10g",
                  loop.queued_until_s, limits.max_lead_s, loop.now_s);
  return {};
}

/// The segment the message describes, before its values: kind, target, timing and start.
SetpointSegment segment_head(const TrajectoryMessage& m) {
  const bool at = m.timing == 0 && m.start_time_s >= 0.0;
  SetpointSegment seg;
  seg.kind = *from_wire<Kind>(m.kind);  // checked by check_fields
  seg.target = *from_wire<LoopTarget>(m.target);
  seg.chunk_seq = m.chunk_seq;
  seg.blend_s = m.blend_s;
  seg.timing = m.timing == 1 ? SetpointSegment::Timing::append
                             : (at ? SetpointSegment::Timing::at : SetpointSegment::Timing::now);
  seg.start_s = at ? m.start_time_s : 0.0;
  return seg;
}

/// Each sample in range, and each step between samples within the step and slope limits.
Verdict check_samples(std::span<const double> v, double period_s, const Range& range) {
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (v[i] < range.min || v[i] > range.max)
      return reject(RejectReason::out_of_range, "values[%zu] = %.6g %s is outside %.6g..%.6g", i, v[i], range.unit,
                    range.min, range.max);
    if (i == 0) continue;
    const double step = std::abs(v[i] - v[i - 1]);
    if (step > range.max_step)
      return reject(RejectReason::step_too_large, "values[%zu] jumps %.6g %s from the sample before (limit %.6g)", i, step,
                    range.unit, range.max_step);
    if (step / period_s > range.max_slope)
      return reject(RejectReason::slope_too_large, "values[%zu] changes at %.6g %s/s (limit %.6g)", i, step / period_s,
                    range.unit, range.max_slope);
  }
  return {};
}

/// A chunk of samples, checked and cut into contiguous pieces of at most kMaxValues.
Verdict cut_samples(const TrajectoryMessage& m, const SetpointLimits& limits, const LoopView& loop,
                    const SetpointSegment& seg, std::vector<SetpointSegment>& out) {
  const std::size_t n = m.values.size();
  if (n == 0) return reject(RejectReason::malformed, "a samples chunk has no values");
  if (static_cast<int>(n) > limits.max_chunk_samples)
    return reject(RejectReason::chunk_too_large, "%zu samples, the limit is %d per chunk", n, limits.max_chunk_samples);
  if (m.period_s < loop.period_s - 1e-12 || m.period_s > 1.0)
    return reject(RejectReason::bad_period, "period_s %.6g is outside %.6g (the loop period) .. 1 s", m.period_s, loop.period_s);
  if (Verdict v = check_samples(m.values, m.period_s, range_for(seg.target, limits)); !v.ok()) return v;
  const int pieces = static_cast<int>((n + SetpointSegment::kMaxValues - 1) / SetpointSegment::kMaxValues);
  if (loop.queued_segments + pieces > SetpointSchedule::kCapacity)
    return reject(RejectReason::queue_full, "the loop's queue holds %d segments; %d more do not fit (capacity %d)",
                  loop.queued_segments, pieces, SetpointSchedule::kCapacity);
  for (int p = 0; p < pieces; ++p) {
    SetpointSegment piece = seg;
    const std::size_t first = static_cast<std::size_t>(p) * SetpointSegment::kMaxValues;
    piece.count = static_cast<int>(std::min<std::size_t>(SetpointSegment::kMaxValues, n - first));
    std::copy_n(m.values.begin() + static_cast<std::ptrdiff_t>(first), piece.count, piece.values.begin());
    piece.period_s = m.period_s;
    if (p > 0) {
      piece.continues = true;
      piece.timing = SetpointSegment::Timing::append;
      piece.blend_s = 0.0;
      piece.start_s = 0.0;
    }
    piece.end_s = piece.start_s + piece.count * m.period_s;
    out.push_back(piece);
  }
  return {};
}

/// What a parametric segment spans and how fast it changes at most.
struct Span {
  double lo = 0.0, hi = 0.0, slope = 0.0;
};

/// A sine's or multisine's span (offset -+ the sum of amplitudes) and steepest slope (the sum of 2 pi f a).
Verdict sine_span(const TrajectoryMessage& m, const LoopView& loop, Kind kind, Span& span) {
  const std::size_t n = m.values.size();
  const std::size_t terms = (n - 1) / 3;
  if (n < 4 || (n - 1) % 3 != 0 || (kind == Kind::sine && n != 4) || terms > SetpointSegment::kMaxSineTerms)
    return reject(RejectReason::malformed, "%s takes [offset, a1, f1_Hz, phi1_rad, ...] (%s), got %zu values",
                  kind == Kind::sine ? "sine" : "multisine", kind == Kind::sine ? "4 values" : "1 + 3k values, k <= 8", n);
  double amp = 0.0;
  for (std::size_t i = 1; i < n; i += 3) {
    const double a = std::abs(m.values[i]), f = m.values[i + 1];
    if (f < 0.0 || f > 0.5 / loop.period_s)
      return reject(RejectReason::bad_argument, "frequency %.6g Hz is outside 0..%.6g Hz (Nyquist)", f, 0.5 / loop.period_s);
    amp += a;
    span.slope += 2.0 * std::numbers::pi * f * a;
  }
  span.lo = m.values[0] - amp;
  span.hi = m.values[0] + amp;
  return {};
}

/// The span of a hold, ramp or (multi)sine, its end time set in `seg`; refuses a wrong number of values.
Verdict parametric_span(const TrajectoryMessage& m, const LoopView& loop, SetpointSegment& seg, Span& span) {
  const std::size_t n = m.values.size();
  const double inf = std::numeric_limits<double>::infinity();
  const double end_s = m.duration_s > 0.0 ? seg.start_s + m.duration_s : inf;
  switch (seg.kind) {
    case Kind::hold:
      if (n != 1) return reject(RejectReason::malformed, "hold takes 1 value [level], got %zu", n);
      span = {m.values[0], m.values[0], 0.0};
      seg.end_s = end_s;
      return {};
    case Kind::ramp:
      if (n != 2) return reject(RejectReason::malformed, "ramp takes 2 values [from, to], got %zu", n);
      if (!(m.duration_s > 0.0)) return reject(RejectReason::bad_duration, "a ramp needs duration_s > 0");
      span.lo = std::min(m.values[0], m.values[1]);
      span.hi = std::max(m.values[0], m.values[1]);
      span.slope = (span.hi - span.lo) / m.duration_s;
      seg.end_s = inf;  // then holds `to`
      return {};
    case Kind::sine:
    case Kind::multisine:
      seg.end_s = end_s;
      return sine_span(m, loop, seg.kind, span);
    case Kind::samples:
      break;
  }
  return reject(RejectReason::malformed, "kind %u is not parametric", m.kind);
}

/// A hold, ramp or (multi)sine: one segment, whose whole span and steepest slope must fit the limits.
Verdict parametric_segment(const TrajectoryMessage& m, const SetpointLimits& limits, const LoopView& loop,
                           SetpointSegment seg, std::vector<SetpointSegment>& out) {
  if (loop.queued_segments + 1 > SetpointSchedule::kCapacity)
    return reject(RejectReason::queue_full, "the loop's queue is full (%d segments)", SetpointSchedule::kCapacity);
  Span span;
  if (Verdict v = parametric_span(m, loop, seg, span); !v.ok()) return v;
  const Range range = range_for(seg.target, limits);
  if (span.lo < range.min || span.hi > range.max)
    return reject(RejectReason::out_of_range, "the segment spans %.6g..%.6g %s, outside %.6g..%.6g", span.lo, span.hi,
                  range.unit, range.min, range.max);
  // Per loop cycle the envelope allows min(max_step, max_slope * period): a segment must fit both.
  const double max_slope = std::min(range.max_slope, range.max_step / loop.period_s);
  if (span.slope > max_slope)
    return reject(RejectReason::slope_too_large, "the segment changes at up to %.6g %s/s (limit %.6g)", span.slope,
                  range.unit, max_slope);
  seg.count = static_cast<int>(m.values.size());
  std::copy(m.values.begin(), m.values.end(), seg.values.begin());
  if (seg.kind == Kind::ramp) {
    seg.values[2] = m.duration_s;
    seg.count = 3;
  }
  out.push_back(seg);
  return {};
}

}  // namespace

Verdict validate_trajectory(const TrajectoryMessage& m, const SetpointLimits& limits, const LoopView& loop,
                            std::vector<SetpointSegment>& out) {
  if (Verdict v = check_fields(m, loop); !v.ok()) return v;
  if (Verdict v = check_timing(m, limits, loop); !v.ok()) return v;
  const SetpointSegment seg = segment_head(m);
  return seg.kind == Kind::samples ? cut_samples(m, limits, loop, seg, out) : parametric_segment(m, limits, loop, seg, out);
}

bool start_step_allowed(const SetpointSegment& seg, double from, double first_value,
                        const SetpointLimits& limits) noexcept {
  const Range range = range_for(seg.target, limits);
  const double step = std::abs(first_value - from);
  if (step <= range.max_step) return true;
  // A raised-cosine blend of length T over a step h has a peak slope of pi h / (2 T).
  return seg.blend_s > 0.0 && std::numbers::pi * step / (2.0 * seg.blend_s) <= range.max_slope;
}

Verdict validate_command(std::uint8_t kind, std::uint8_t argument, std::string_view client_id, std::uint64_t seq) {
  if (client_id.empty()) return reject(RejectReason::malformed, "client_id is empty");
  if (seq == 0) return reject(RejectReason::malformed, "command_seq must be nonzero");
  const auto command = from_wire<CommandKind>(kind);
  if (!command) return reject(RejectReason::unknown_command, "command kind %u is not 1..7", kind);
  if (command == CommandKind::set_mode && !from_wire<control::ControllerMode>(argument))
    return reject(RejectReason::bad_argument, "mode %u is not 0..3 (pid, inverse_pid, inverse_pid_dob, inverse_pid_dob_ff)", argument);
  if (command == CommandKind::set_target && !from_wire<LoopTarget>(argument))
    return reject(RejectReason::bad_argument, "target %u is not 0 (displacement) or 1 (voltage)", argument);
  return {};
}

}  // namespace pvcgel::daemon
