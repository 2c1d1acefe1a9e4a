// STUB of realtime_tools::RealtimeBuffer for tests (tests/ros2_stubs/README.md): not ROS 2.
// The same contract: writeFromNonRT copies under a mutex and marks new data; readFromRT takes
// the new data with try_lock (never blocks) and otherwise returns the previous one.
#pragma once

#include <memory>
#include <mutex>

namespace realtime_tools
{
template <class T>
class RealtimeBuffer
{
public:
  RealtimeBuffer() : rt_(new T()), non_rt_(new T()) {}
  RealtimeBuffer(const RealtimeBuffer &) = delete;
  RealtimeBuffer & operator=(const RealtimeBuffer &) = delete;
  T * readFromRT()
  {
    std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
    if (lock.owns_lock() && fresh_) {
      rt_.swap(non_rt_);
      fresh_ = false;
    }
    return rt_.get();
  }
  void writeFromNonRT(const T & data)
  {
    std::lock_guard<std::mutex> lock(mutex_);
    *non_rt_ = data;
    fresh_ = true;
  }
  void initRT(const T & data)
  {
    *rt_ = data;
    *non_rt_ = data;
    fresh_ = false;
  }

private:
  std::unique_ptr<T> rt_, non_rt_;
  bool fresh_ = false;
  std::mutex mutex_;
};
}  // namespace realtime_tools
