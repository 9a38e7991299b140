#pragma once
/// @file
/// Setpoints received ahead of time (over DDS), kept by the real-time thread
/// and played at their timestamps, with preview for the controller.

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <string_view>

#include "control/enum_table.hpp"

namespace pvcgel::daemon {

/// What the setpoints drive: the displacement (closed loop, um) or the
/// amplifier voltage directly (open loop, V; for identification experiments).
enum class LoopTarget : std::uint8_t { displacement = 0, voltage = 1 };
inline constexpr auto kLoopTargetNames =
    enum_table<LoopTarget::displacement, LoopTarget::voltage>({"displacement", "voltage"});
constexpr const auto& names_of(LoopTarget) noexcept { return kLoopTargetNames; }
constexpr std::string_view to_string(LoopTarget t) noexcept { return kLoopTargetNames.to_string(t); }

/// One validated piece of a trajectory, in loop time. Fixed size and trivially
/// copyable so it crosses the lock-free queue by value; a long chunk of
/// samples arrives as several contiguous pieces.
struct SetpointSegment {
  enum class Kind : std::uint8_t { samples, hold, ramp, sine, multisine };
  static constexpr int kMaxValues = 128;
  static constexpr int kMaxSineTerms = 8;

  Kind kind = Kind::hold;
  LoopTarget target = LoopTarget::displacement;
  /// When it starts. `at`: at `start_s`, dropping whatever is queued from
  /// there on; `now`: the same at the cycle that receives it; `append`: where
  /// the last queued segment ends (or now, when nothing is queued). For `now`
  /// and `append` the loop moves `start_s` and `end_s` together, so the
  /// sender gives them relative to 0.
  enum class Timing : std::uint8_t { at, now, append };
  Timing timing = Timing::append;
  std::uint64_t chunk_seq = 0;
  double start_s = 0.0;
  /// The segment covers [start_s, end_s); infinity: until replaced.
  double end_s = std::numeric_limits<double>::infinity();
  double period_s = 0.0;  ///< samples only
  double blend_s = 0.0;   ///< raised-cosine blend from the setpoint in force when it starts
  /// A later piece of the same chunk (appended contiguously): it continues the
  /// chunk's blend, so a blend longer than one piece is one continuous curve.
  /// (An unblended chunk appended contiguously while a blend is still running
  /// continues it too: a blend longer than a chunk is one curve as well.)
  bool continues = false;
  int count = 0;          ///< values used
  /// samples: the setpoints; hold: [level]; ramp: [from, to, ramp_time_s]; sine and multisine:
  /// [offset, a1, f1_Hz, phi1_rad, ...].
  std::array<double, kMaxValues> values{};
};

inline constexpr auto kSegmentKindNames = enum_table<SetpointSegment::Kind::samples, SetpointSegment::Kind::multisine>(
    {"samples", "hold", "ramp", "sine", "multisine"});
constexpr const auto& names_of(SetpointSegment::Kind) noexcept { return kSegmentKindNames; }
constexpr std::string_view to_string(SetpointSegment::Kind k) noexcept { return kSegmentKindNames.to_string(k); }
inline constexpr auto kSegmentTimingNames =
    enum_table<SetpointSegment::Timing::at, SetpointSegment::Timing::append>({"at", "now", "append"});
constexpr const auto& names_of(SetpointSegment::Timing) noexcept { return kSegmentTimingNames; }
constexpr std::string_view to_string(SetpointSegment::Timing t) noexcept { return kSegmentTimingNames.to_string(t); }

/// The real-time side's queue of segments, time-ordered. Every member is
/// noexcept and allocation-free after construction.
class SetpointSchedule final {
 public:
  static constexpr int kCapacity = 256;  ///< 32 s of 1 kHz samples in 128-sample pieces

  SetpointSchedule();

  /// Queue a segment that arrived during the cycle at loop time `now_s`
  /// (`current_value`: the setpoint in force, the blend's start). False when
  /// full (the segment is dropped and the caller reports it).
  bool add(const SetpointSegment& seg, double now_s, double current_value) noexcept;
  /// Drop everything queued.
  void clear() noexcept { head_ = size_ = 0; }
  /// Retire segments that ended before `now_s` (call once per cycle, before `value_at`).
  void advance(double now_s) noexcept;
  /// The setpoint at `t_s` (now or ahead, for preview). False when no segment
  /// covers `t_s` (nothing queued yet, a gap, or the queue ran dry).
  bool value_at(double t_s, double& value) const noexcept;
  /// chunk_seq of the segment covering `t_s` (0: none).
  [[nodiscard]] std::uint64_t chunk_at(double t_s) const noexcept;
  /// The last queued segment's own value at its end, without a blend (the
  /// client's curve an appended chunk continues). Call only when not empty.
  [[nodiscard]] double tail_value() const noexcept;
  /// Loop time up to which setpoints are queued (-inf when empty).
  [[nodiscard]] double queued_until_s() const noexcept;
  [[nodiscard]] int size() const noexcept { return size_; }
  [[nodiscard]] bool empty() const noexcept { return size_ == 0; }

 private:
  struct Slot {
    SetpointSegment seg;
    double blend_from = 0.0;
    double blend_start_s = 0.0;  // where the chunk's blend began (its first piece's start)
    double blend_s = 0.0;        // the chunk's blend length
  };
  [[nodiscard]] const Slot& at(int i) const noexcept { return slots_[static_cast<std::size_t>((head_ + i) % kCapacity)]; }
  Slot& at(int i) noexcept { return slots_[static_cast<std::size_t>((head_ + i) % kCapacity)]; }
  [[nodiscard]] int find(double t_s) const noexcept;
  [[nodiscard]] double raw_value(int i, double t_s) const noexcept;

  std::unique_ptr<std::array<Slot, kCapacity>> storage_;
  std::array<Slot, kCapacity>& slots_;
  int head_ = 0;
  int size_ = 0;
};

/// Value of a segment alone at `t_s` (no blend, no neighbours; samples hold
/// their last value). Shared by the loop and the validator.
double segment_value(const SetpointSegment& seg, double t_s) noexcept;

}  // namespace pvcgel::daemon
