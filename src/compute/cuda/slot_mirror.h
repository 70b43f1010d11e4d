#pragma once
// The host's record of a keyed store that lives on the device (DESIGN.md: "map, feature positions and pose
// history live on the device"): which slot of the device array holds which key, and the value that slot
// holds there. A call asks for the slot of each key it needs and learns whether the value has to be sent:
// when the key is new, when its value changed (compared byte for byte, never by a hash), or when the device
// copy was lost (the store grew, or a call failed). Everything else is already on the device. Slots of keys
// no call has asked for in `keep_calls` calls are reused. Plain C++17: the host tests check it without a GPU.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <type_traits>
#include <unordered_map>
#include <vector>

namespace mcslam::compute::cuda {

template <typename Key, typename Value, typename Hash = std::hash<Key>>
class SlotMirror {
  static_assert(std::is_trivially_copyable_v<Value>, "values are sent to the device as bytes");

 public:
  // min_capacity: slots of the first device array; keep_calls: how many calls an unused key keeps its slot.
  explicit SlotMirror(int min_capacity = 1024, int keep_calls = 64)
      : min_capacity_(min_capacity > 0 ? min_capacity : 1), keep_calls_(keep_calls > 0 ? keep_calls : 1) {}

  // A call: BeginCall, Touch every key it will ask for, MakeRoom for the ones Touch did not find, then
  // Acquire each key.
  void BeginCall() {
    ++call_;
    missing_ = 0;
  }

  // Marks `key` as wanted by this call, so that making room does not free its slot.
  void Touch(const Key& key) {
    const auto it = index_.find(key);
    if (it == index_.end()) {
      ++missing_;
    } else {
      slots_[static_cast<size_t>(it->second)].last_call = call_;
    }
  }

  // Makes sure every key touched in this call can have a slot: slots of keys unused for keep_calls calls are
  // freed, and if that is not enough the store grows (at least doubling). Growing means a new device array:
  // nothing on the device is valid any more (generation() changes) and every key is sent again when next
  // asked for.
  void MakeRoom() {
    if (free_.size() >= missing_) return;
    EvictUnusedBefore(call_ - keep_calls_ + 1);
    if (free_.size() >= missing_) return;
    const size_t live = slots_.size() - free_.size();
    size_t capacity = std::max<size_t>(slots_.size() * 2, min_capacity_);
    while (capacity < live + missing_) capacity *= 2;
    Grow(capacity);
  }

  // The slot of `key` in this call; *send is set when `value` must be copied there before the device reads
  // it. A key asked for twice in one call is an error (std::invalid_argument): its two values could differ.
  int Acquire(const Key& key, const Value& value, bool* send) {
    auto [it, inserted] = index_.try_emplace(key, -1);
    if (inserted) {
      if (free_.empty()) {
        index_.erase(it);
        throw std::logic_error("SlotMirror: a key that was not touched before MakeRoom");
      }
      it->second = free_.back();
      free_.pop_back();
      Slot& s = slots_[it->second];
      s.key = key;
      s.live = true;
      s.sent_generation = 0;  // never a valid generation: sent below
    }
    Slot& s = slots_[it->second];
    if (!inserted && s.acquired_call == call_)
      throw std::invalid_argument("SlotMirror: a key is asked for twice in one call");
    s.last_call = s.acquired_call = call_;
    *send = s.sent_generation != generation_ || std::memcmp(&s.value, &value, sizeof(Value)) != 0;
    if (*send) {
      std::memcpy(&s.value, &value, sizeof(Value));
      s.sent_generation = generation_;
    }
    return it->second;
  }

  // The device copy of this call's sends did not arrive (a copy or a kernel failed): forget what the device
  // holds, so that the next call sends every key it asks for.
  void Invalidate() { ++generation_; }

  size_t capacity() const { return slots_.size(); }                // slots the device array must have
  size_t live() const { return slots_.size() - free_.size(); }     // keys that hold a slot
  uint64_t generation() const { return generation_; }              // changes whenever the device copy is lost

 private:
  struct Slot {
    Key key{};
    Value value{};
    int64_t last_call = -1;      // the last call that touched or asked for it
    int64_t acquired_call = -1;  // the last call that asked for it
    uint64_t sent_generation = 0;
    bool live = false;
  };

  // Frees the slots of keys last used before `call`.
  void EvictUnusedBefore(int64_t call) {
    for (size_t i = 0; i < slots_.size(); ++i) {
      Slot& s = slots_[i];
      if (!s.live || s.last_call >= call) continue;
      index_.erase(s.key);
      s.live = false;
      free_.push_back(static_cast<int>(i));
    }
  }

  void Grow(size_t capacity) {
    const size_t old = slots_.size();
    slots_.resize(capacity);
    // Lowest slots handed out first (free_ is taken from the back).
    std::vector<int> added;
    for (size_t i = capacity; i-- > old;) added.push_back(static_cast<int>(i));
    free_.insert(free_.begin(), added.begin(), added.end());
    ++generation_;
  }

  size_t min_capacity_;
  int64_t keep_calls_;
  int64_t call_ = 0;
  size_t missing_ = 0;  // keys touched in this call that hold no slot
  uint64_t generation_ = 1;
  std::vector<Slot> slots_;
  std::vector<int> free_;
  std::unordered_map<Key, int, Hash> index_;
};

}  // namespace mcslam::compute::cuda
