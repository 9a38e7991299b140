#include "daemon/record_consumer.hpp"

#include <chrono>

namespace pvcgel::daemon {

RecordConsumer::RecordConsumer(RecordRing& ring, const std::atomic<bool>& loop_done, Recorder* recorder,
                               TelemetryPublisher* publisher)
    : ring_(ring), loop_done_(loop_done), recorder_(recorder), publisher_(publisher), thread_([this] { run(); }) {}

void RecordConsumer::join() {
  thread_.join();
  if (error_) std::rethrow_exception(error_);
}

void RecordConsumer::run() {
  try {
    for (;;) {
      bool any = false;
      while (auto r = ring_.pop()) {
        any = true;
        if (recorder_) recorder_->write(*r);
        if (publisher_) publisher_->publish(*r);
      }
      if (recorder_) recorder_->flush_if_due();
      if (!any) {
        // The loop's last records are in the ring before loop_done is set: drain, then stop.
        if (loop_done_.load(std::memory_order_acquire) && ring_.size() == 0) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
      }
    }
    if (recorder_) recorder_->finish();
  } catch (...) {
    error_ = std::current_exception();
  }
}

}  // namespace pvcgel::daemon
