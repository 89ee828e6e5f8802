// WMO world layer: a growable array whose storage can be shared with readers that
// outlive a reallocation (NumPy views of the world's state).
//
// Like std::vector for the world's own use (push_back, pop_back, operator[]), but the
// storage is a std::shared_ptr<T[]>: when the array grows past its capacity it moves
// to a new allocation and the old one stays alive for as long as a reader holds it
// (shared()). Such a reader then sees a detached copy, never freed memory. The world
// never shrinks the allocation, so a reader of the current storage stays valid across
// removals (rows beyond size() hold stale values).
#pragma once

#include <algorithm>
#include <cstddef>
#include <memory>

namespace wmo {

template <class T>
class SharedArray {
 public:
  int size() const { return size_; }
  int capacity() const { return capacity_; }
  bool empty() const { return size_ == 0; }
  T& operator[](int i) { return data_[i]; }
  const T& operator[](int i) const { return data_[i]; }
  T* data() { return data_.get(); }
  const T* data() const { return data_.get(); }
  T* begin() { return data(); }
  T* end() { return data() + size_; }
  const T* begin() const { return data(); }
  const T* end() const { return data() + size_; }
  T& back() { return data_[size_ - 1]; }

  /// The storage itself, for readers that must keep it alive (see the file comment).
  const std::shared_ptr<T[]>& shared() const { return data_; }

  void reserve(int n) {
    if (n <= capacity_) return;
    std::shared_ptr<T[]> next(new T[static_cast<std::size_t>(n)]);
    std::copy(begin(), end(), next.get());
    data_ = std::move(next);
    capacity_ = n;
  }
  void push_back(const T& v) {
    if (size_ == capacity_) reserve(std::max(8, 2 * capacity_));
    data_[size_++] = v;
  }
  void pop_back() { --size_; }

 private:
  std::shared_ptr<T[]> data_;
  int size_ = 0;
  int capacity_ = 0;
};

}  // namespace wmo
