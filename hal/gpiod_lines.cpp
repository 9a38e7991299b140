#include "hal/gpiod_lines.hpp"

#include <gpiod.h>

#include <cerrno>
#include <cstring>
#include <ctime>

#include "control/config_error.hpp"

namespace pvcgel::hal {

using control::ConfigError;

namespace {

constexpr const char* kConsumer = "pvcgeld";

gpiod_line* find_line(gpiod_chip* chip, const std::string& spec, const std::string& key) {
  const bool is_offset = !spec.empty() && spec.find_first_not_of("0123456789") == std::string::npos;
  gpiod_line* line = is_offset ? gpiod_chip_get_line(chip, static_cast<unsigned>(std::stoul(spec)))
                               : gpiod_chip_find_line(chip, spec.c_str());
  if (!line)
    throw ConfigError(key, "no line '" + spec + "' on chip " + gpiod_chip_name(chip) + " (" + gpiod_chip_label(chip) +
                               ", " + std::to_string(gpiod_chip_num_lines(chip)) + " lines); see gpioinfo");
  return line;
}

int flags(bool active_low) { return active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0; }

std::string busy(const std::string& key, gpiod_line* line) {
  const char* consumer = gpiod_line_consumer(line);
  return key + ": cannot request the line: " + std::strerror(errno) +
         (consumer ? std::string(" (held by '") + consumer + "')" : std::string());
}

/// Drains pending events; true if there was at least one.
bool drain_events(gpiod_line* line, bool& ok) noexcept {
  bool any = false;
  const timespec zero{0, 0};
  for (;;) {
    const int rc = gpiod_line_event_wait(line, &zero);
    if (rc == 0) return any;
    gpiod_line_event event;
    if (rc < 0 || gpiod_line_event_read(line, &event) != 0) {
      ok = false;
      return any;
    }
    any = true;
  }
}

}  // namespace

void GpiodLines::ChipCloser::operator()(gpiod_chip* chip) const noexcept { gpiod_chip_close(chip); }
void GpiodLines::LineReleaser::operator()(gpiod_line* line) const noexcept { gpiod_line_release(line); }

GpiodLines::GpiodLines(const GpioConfig& c) {
  chip_.reset(gpiod_chip_open_lookup(c.chip.c_str()));
  if (!chip_) throw ConfigError("hal.gpio.chip", "cannot open GPIO chip '" + c.chip + "': " + std::strerror(errno) + " (see gpiodetect)");

  gpiod_line* hv = find_line(chip_.get(), c.hv_enable_line, "hal.gpio.hv_enable_line");
  // Requested inactive: the amplifier stays disabled until the loop arms.
  if (gpiod_line_request_output_flags(hv, kConsumer, flags(c.hv_enable_active_low), 0) != 0)
    throw ConfigError("hal.gpio.hv_enable_line", busy("hal.gpio.hv_enable_line", hv));
  hv_enable_.reset(hv);

  gpiod_line* estop = find_line(chip_.get(), c.estop_line, "hal.gpio.estop_line");
  if (gpiod_line_request_both_edges_events_flags(estop, kConsumer, flags(c.estop_active_low)) != 0)
    throw ConfigError("hal.gpio.estop_line", busy("hal.gpio.estop_line", estop));
  estop_.reset(estop);

  if (!c.amp_fault_line.empty()) {
    gpiod_line* fault = find_line(chip_.get(), c.amp_fault_line, "hal.gpio.amp_fault_line");
    if (gpiod_line_request_both_edges_events_flags(fault, kConsumer, flags(c.amp_fault_active_low)) != 0)
      throw ConfigError("hal.gpio.amp_fault_line", busy("hal.gpio.amp_fault_line", fault));
    amp_fault_.reset(fault);
  }
}

GpiodLines::~GpiodLines() {
  // What the line does after release depends on the chip driver; the wiring
  // must make "not driven" mean disabled (see README).
  if (hv_enable_) gpiod_line_set_value(hv_enable_.get(), 0);
}

bool GpiodLines::set_enable(bool enabled) noexcept { return gpiod_line_set_value(hv_enable_.get(), enabled ? 1 : 0) == 0; }

InterlockInputs GpiodLines::poll() noexcept {
  InterlockInputs in;
  in.edge_seen = drain_events(estop_.get(), in.ok);
  const int estop = gpiod_line_get_value(estop_.get());
  in.estop_active = estop != 0;  // an unreadable line (-1) counts as pressed
  in.ok = in.ok && estop >= 0;
  if (amp_fault_) {
    in.edge_seen = drain_events(amp_fault_.get(), in.ok) || in.edge_seen;
    const int fault = gpiod_line_get_value(amp_fault_.get());
    in.amp_fault_active = fault != 0;
    in.ok = in.ok && fault >= 0;
  }
  return in;
}

}  // namespace pvcgel::hal
