#include "daemon/setpoint_schedule.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace pvcgel::daemon {

double segment_value(const SetpointSegment& seg, double t_s) noexcept {
  const auto& v = seg.values;
  const double tau = std::max(0.0, t_s - seg.start_s);
  switch (seg.kind) {
    case SetpointSegment::Kind::samples: {
      const double x = tau / seg.period_s;
      const int last = seg.count - 1;
      const int i0 = std::min(static_cast<int>(x), last);
      if (i0 >= last) return v[static_cast<std::size_t>(last)];
      const double frac = x - i0;
      return v[static_cast<std::size_t>(i0)] + frac * (v[static_cast<std::size_t>(i0) + 1] - v[static_cast<std::size_t>(i0)]);
    }
    case SetpointSegment::Kind::hold:
      return v[0];
    case SetpointSegment::Kind::ramp:
      return v[2] > 0.0 ? v[0] + (v[1] - v[0]) * std::min(1.0, tau / v[2]) : v[1];
    case SetpointSegment::Kind::sine:
    case SetpointSegment::Kind::multisine: {
      double r = v[0];
      for (int i = 1; i + 2 < seg.count; i += 3)
        r += v[static_cast<std::size_t>(i)] *
             std::sin(2.0 * std::numbers::pi * v[static_cast<std::size_t>(i) + 1] * tau + v[static_cast<std::size_t>(i) + 2]);
      return r;
    }
  }
  return v[0];
}

SetpointSchedule::SetpointSchedule()
    : storage_(std::make_unique<std::array<Slot, kCapacity>>()), slots_(*storage_) {}

bool SetpointSchedule::add(const SetpointSegment& in, double now_s, double current_value) noexcept {
  SetpointSegment seg = in;
  double start = seg.start_s;
  if (seg.timing == SetpointSegment::Timing::now) {
    start = now_s;
  } else if (seg.timing == SetpointSegment::Timing::append) {
    const double tail = queued_until_s();
    start = std::isfinite(tail) && tail > now_s ? tail : now_s;
  }
  if (seg.timing != SetpointSegment::Timing::at) {
    seg.end_s = start + (seg.end_s - seg.start_s);
    seg.start_s = start;
  }
  if (seg.timing != SetpointSegment::Timing::append) {
    // Replace: nothing queued survives past the new start.
    while (size_ > 0 && at(size_ - 1).seg.start_s >= seg.start_s) --size_;
    if (size_ > 0 && at(size_ - 1).seg.end_s > seg.start_s) at(size_ - 1).seg.end_s = seg.start_s;
  }
  if (size_ == kCapacity) return false;
  double from = current_value;
  if (seg.start_s > now_s) value_at(seg.start_s - 1e-9, from);
  Slot slot{seg, from, seg.start_s, seg.blend_s};
  const Slot* prev_slot = size_ > 0 ? &at(size_ - 1) : nullptr;
  const bool blend_running = prev_slot && seg.timing == SetpointSegment::Timing::append && seg.blend_s <= 0.0 &&
                             std::abs(prev_slot->seg.end_s - seg.start_s) < 1e-9 && prev_slot->blend_s > 0.0 &&
                             prev_slot->blend_start_s + prev_slot->blend_s > seg.start_s;
  if (prev_slot && (seg.continues || blend_running)) {
    // Continue the blend across the piece (or chunk) boundary: it used to be cut after one piece, then step.
    const Slot& prev = *prev_slot;
    slot.blend_from = prev.blend_from;
    slot.blend_start_s = prev.blend_start_s;
    slot.blend_s = prev.blend_s;
  }
  at(size_) = slot;
  ++size_;
  return true;
}

void SetpointSchedule::advance(double now_s) noexcept {
  while (size_ > 0 && at(0).seg.end_s <= now_s) {
    head_ = (head_ + 1) % kCapacity;
    --size_;
  }
}

int SetpointSchedule::find(double t_s) const noexcept {
  for (int i = 0; i < size_; ++i) {
    const auto& s = at(i).seg;
    if (t_s < s.start_s) return -1;  // time-ordered: a gap
    if (t_s < s.end_s) return i;
  }
  return -1;
}

double SetpointSchedule::raw_value(int i, double t_s) const noexcept {
  const auto& s = at(i).seg;
  if (s.kind == SetpointSegment::Kind::samples && i + 1 < size_) {
    // Interpolate across a piece boundary into the contiguous next piece.
    const double last_t = s.start_s + (s.count - 1) * s.period_s;
    const auto& next = at(i + 1).seg;
    if (t_s > last_t && std::abs(next.start_s - s.end_s) < 1e-9 && next.blend_s <= 0.0) {
      const double frac = (t_s - last_t) / (next.start_s - last_t);
      const double a = s.values[static_cast<std::size_t>(s.count - 1)];
      return a + frac * (segment_value(next, next.start_s) - a);
    }
  }
  return segment_value(s, t_s);
}

bool SetpointSchedule::value_at(double t_s, double& value) const noexcept {
  const int i = find(t_s);
  if (i < 0) return false;
  const auto& slot = at(i);
  double v = raw_value(i, t_s);
  const double since = t_s - slot.blend_start_s;
  if (slot.blend_s > 0.0 && since < slot.blend_s) {
    const double s = 0.5 * (1.0 - std::cos(std::numbers::pi * since / slot.blend_s));
    v = slot.blend_from + (v - slot.blend_from) * s;
  }
  value = v;
  return true;
}

std::uint64_t SetpointSchedule::chunk_at(double t_s) const noexcept {
  const int i = find(t_s);
  return i < 0 ? 0 : at(i).seg.chunk_seq;
}

double SetpointSchedule::tail_value() const noexcept {
  const auto& seg = at(size_ - 1).seg;
  return segment_value(seg, std::isfinite(seg.end_s) ? seg.end_s - 1e-9 : seg.start_s);
}

double SetpointSchedule::queued_until_s() const noexcept {
  return size_ == 0 ? -std::numeric_limits<double>::infinity() : at(size_ - 1).seg.end_s;
}

}  // namespace pvcgel::daemon
