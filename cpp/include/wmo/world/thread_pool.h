// WMO world layer: a small fixed pool of worker threads for the step's parallel stages.
//
// run(fn) calls fn(t) once for every t in [0, size()), t = 0 on the calling thread and
// the others on the workers, and returns when all have returned. Callers split their
// work by t into contiguous, fixed ranges and merge the results in t order, so the
// outcome never depends on timing (the world's results are bit-identical for any
// thread count). Between runs a worker spins for a short while (kSpin in
// thread_pool.cpp), then sleeps on a condition variable: an idle pool costs nothing.
// WideContacts' passes run on it as a ParallelTeam (contact_solver.h).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "wmo/dynamics/contact_solver.h"

namespace wmo {

class ThreadPool final : public ParallelTeam {
 public:
  /// `threads` >= 1 in all, the calling thread included (1: no workers).
  explicit ThreadPool(int threads);
  ~ThreadPool() override;
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int size() const override { return static_cast<int>(workers_.size()) + 1; }

  /// Runs fn(0) ... fn(size() - 1) concurrently and waits for all of them. An exception
  /// thrown by any call is rethrown here (the first one) after all have finished.
  void run(const std::function<void(int)>& fn) override;

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
  // Bumped by run() (under mutex_); workers run each generation once. Atomic, as is
  // pending_, so that a worker and run() can first spin on them (kSpin) before they
  // sleep: the solver's passes call run() every few hundred microseconds, and waking a
  // sleeping thread costs tens of microseconds on a busy system (measured ~37 us a
  // run on the 2-core VM: 0.6 ms of the pyramid's step).
  std::atomic<std::uint64_t> generation_{0};
  std::atomic<int> pending_{0};   // workers still running the current job
  bool stop_ = false;
  std::exception_ptr error_;
};

}  // namespace wmo
