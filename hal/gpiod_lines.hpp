#pragma once
/// @file
/// GpioLines on the GPIO character device through libgpiod v1.6 (Debian 12).

#include <memory>

#include "hal/gpio_lines.hpp"

struct gpiod_chip;
struct gpiod_line;

namespace pvcgel::hal {

/// Requests the interlock lines with consumer "pvcgeld": HV enable as an
/// output, initially inactive (disabled); e-stop and amplifier fault as inputs
/// with both-edge events. Releases them (after driving HV enable inactive) on
/// destruction.
class GpiodLines final : public GpioLines {
 public:
  /// @throws control::ConfigError naming the hal.gpio key whose chip or line is
  ///   missing or busy.
  explicit GpiodLines(const GpioConfig& config);
  ~GpiodLines() override;

  bool set_enable(bool enabled) noexcept override;
  InterlockInputs poll() noexcept override;

 private:
  struct ChipCloser {
    void operator()(gpiod_chip* chip) const noexcept;
  };
  struct LineReleaser {
    void operator()(gpiod_line* line) const noexcept;
  };
  using LinePtr = std::unique_ptr<gpiod_line, LineReleaser>;

  std::unique_ptr<gpiod_chip, ChipCloser> chip_;
  LinePtr hv_enable_, estop_, amp_fault_;
};

}  // namespace pvcgel::hal
