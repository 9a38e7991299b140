#pragma once
/// @file
/// The one consumer of the loop's records, off the real-time thread: it
/// drains the ring into the recording and the Telemetry publisher until the
/// loop has finished and the ring is empty.

#include <atomic>
#include <exception>
#include <thread>

#include "daemon/realtime_thread.hpp"
#include "daemon/recorder.hpp"
#include "daemon/telemetry_publisher.hpp"

namespace pvcgel::daemon {

class RecordConsumer final {
 public:
  /// Starts the thread. `recorder` and `publisher` may be null (not recording,
  /// no DDS); all four outlive this object.
  RecordConsumer(RecordRing& ring, const std::atomic<bool>& loop_done, Recorder* recorder, TelemetryPublisher* publisher);
  RecordConsumer(const RecordConsumer&) = delete;
  RecordConsumer& operator=(const RecordConsumer&) = delete;

  /// Waits until every record is written and the recording finished.
  /// @throws what writing the recording threw (std::runtime_error naming the file).
  void join();

 private:
  void run();

  RecordRing& ring_;
  const std::atomic<bool>& loop_done_;
  Recorder* recorder_;
  TelemetryPublisher* publisher_;
  std::exception_ptr error_;
  std::thread thread_;
};

}  // namespace pvcgel::daemon
