// WMO world layer: a small fixed pool of worker threads for the step's parallel stages.
//
// run(fn) calls fn(t) once for every t in [0, size()), t = 0 on the calling thread and
// the others on the workers, and returns when all have returned. Callers split their
// work by t into contiguous, fixed ranges and merge the results in t order, so the
// outcome never depends on timing (the world's results are bit-identical for any
// thread count). Workers sleep on a condition variable between runs: an idle pool costs
// nothing.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace wmo {

class ThreadPool {
 public:
  /// `threads` >= 1 in all, the calling thread included (1: no workers).
  explicit ThreadPool(int threads);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int size() const { return static_cast<int>(workers_.size()) + 1; }

  /// Runs fn(0) ... fn(size() - 1) concurrently and waits for all of them. An exception
  /// thrown by any call is rethrown here (the first one) after all have finished.
  void run(const std::function<void(int)>& fn);

  /// [begin, end) of the t-th of size() contiguous, near-equal parts of [0, n).
  static std::pair<std::size_t, std::size_t> part(std::size_t n, int t, int parts) {
    return {n * static_cast<std::size_t>(t) / static_cast<std::size_t>(parts),
            n * static_cast<std::size_t>(t + 1) / static_cast<std::size_t>(parts)};
  }

 private:
  void worker(int t);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable start_, done_;
  const std::function<void(int)>* job_ = nullptr;
  std::uint64_t generation_ = 0;  // bumped by run(); workers run each generation once
  int pending_ = 0;               // workers still running the current job
  bool stop_ = false;
  std::exception_ptr error_;
};

}  // namespace wmo
