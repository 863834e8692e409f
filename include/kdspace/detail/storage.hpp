// Storage<T>: the array behind an index: either its own vector (a std::vector, or a HugePageVector
// whose large arrays lie in huge pages where enabled, detail/huge_pages.hpp), or memory it borrows (a section
// of a memory-mapped index file, see io/index.hpp). The index that holds borrowed storage also holds
// what keeps that memory alive (the mapping), so the storage never outlives it.
//
// Queries read through data() and operator[], one pointer either way: borrowing costs the query path
// nothing.
#pragma once

#include <cstddef>
#include <utility>
#include <vector>

#include "kdspace/detail/huge_pages.hpp"

namespace kdspace::detail {

template <class T>
class Storage {
 public:
  Storage() = default;
  /// Owns `values`.
  explicit Storage(std::vector<T> values) : owned_(std::move(values)) { point_at_owned(); }
  /// Owns `values`: a builder's large arrays, in huge pages where enabled (a function, not a
  /// constructor, so that Storage({first, last}) still means a std::vector).
  static Storage owning(HugePageVector<T> values) {
    Storage s;
    s.large_ = std::move(values);
    s.point_at_owned();
    return s;
  }
  /// Borrows [data, data + size): the caller keeps that memory alive as long as this storage.
  static Storage borrow(const T* data, std::size_t size) {
    Storage s;
    s.data_ = data;
    s.size_ = size;
    s.borrowed_ = true;
    return s;
  }

  Storage(const Storage& o)
      : owned_(o.owned_), large_(o.large_), data_(o.data_), size_(o.size_), borrowed_(o.borrowed_) {
    if (!borrowed_) point_at_owned();
  }
  Storage(Storage&& o) noexcept
      : owned_(std::move(o.owned_)),
        large_(std::move(o.large_)),
        data_(o.data_),
        size_(o.size_),
        borrowed_(o.borrowed_) {
    if (!borrowed_) point_at_owned();
    o.clear();
  }
  Storage& operator=(const Storage& o) {
    if (this != &o) *this = Storage(o);
    return *this;
  }
  Storage& operator=(Storage&& o) noexcept {
    if (this == &o) return *this;
    owned_ = std::move(o.owned_);
    large_ = std::move(o.large_);
    data_ = o.data_;
    size_ = o.size_;
    borrowed_ = o.borrowed_;
    if (!borrowed_) point_at_owned();
    o.clear();
    return *this;
  }

  const T* data() const { return data_; }
  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  const T& operator[](std::size_t i) const { return data_[i]; }
  const T* begin() const { return data_; }
  const T* end() const { return data_ + size_; }
  /// Writable access to owned memory (a builder filling it in place); nullptr when borrowed.
  T* owned_data() {
    if (borrowed_) return nullptr;
    return large_.empty() ? owned_.data() : large_.data();
  }
  /// The values as a vector of their own (the owned one moved out, or borrowed memory copied),
  /// leaving this storage empty: for a change in place (BoxTree::refit), stored back with
  /// Storage(std::move(values)). (A HugePageVector's values are copied.)
  std::vector<T> release() {
    std::vector<T> values = borrowed_ || !large_.empty() ? std::vector<T>(data_, data_ + size_) : std::move(owned_);
    clear();
    return values;
  }
  /// Whether the memory is borrowed (mapped) rather than owned.
  bool borrowed() const { return borrowed_; }
  /// Bytes the array takes: its capacity when owned, its size when borrowed.
  std::size_t memory_bytes() const {
    return (borrowed_ ? size_ : owned_.capacity() + large_.capacity()) * sizeof(T);
  }

  friend bool operator==(const Storage& a, const Storage& b) {
    if (a.size_ != b.size_) return false;
    for (std::size_t i = 0; i < a.size_; ++i)
      if (!(a.data_[i] == b.data_[i])) return false;
    return true;
  }
  friend bool operator!=(const Storage& a, const Storage& b) { return !(a == b); }

 private:
  // At most one of owned_ and large_ holds values.
  void point_at_owned() {
    data_ = large_.empty() ? owned_.data() : large_.data();
    size_ = owned_.size() + large_.size();
  }
  void clear() {  // frees the arrays too (release() copies out of large_)
    std::vector<T>().swap(owned_);
    HugePageVector<T>().swap(large_);
    data_ = nullptr;
    size_ = 0;
    borrowed_ = false;
  }

  std::vector<T> owned_;
  HugePageVector<T> large_;
  const T* data_ = nullptr;
  std::size_t size_ = 0;
  bool borrowed_ = false;
};

}  // namespace kdspace::detail
