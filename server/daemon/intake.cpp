#include "daemon/intake.hpp"

#include <algorithm>
#include <cstring>
#include <utility>

namespace ladder::daemon {

bool Inbox::push(Incoming in, std::size_t cap) {
  auto q = std::find_if(queues_.begin(), queues_.end(), [&](const auto& e) { return e.first == in.sender; });
  if (q == queues_.end()) {
    if (cap == 0) return false;
    queues_.emplace_back(in.sender, std::deque<Incoming>{});
    q = queues_.end() - 1;
  } else if (q->second.size() >= cap) {
    return false;
  }
  q->second.push_back(std::move(in));
  ++total_;
  return true;
}

void Inbox::take(std::size_t n, std::vector<Incoming>& out) {
  while (n > 0 && total_ > 0) {
    if (next_ >= queues_.size()) next_ = 0;
    std::deque<Incoming>& q = queues_[next_].second;
    out.push_back(std::move(q.front()));
    q.pop_front();
    --total_, --n;
    if (q.empty())
      queues_.erase(queues_.begin() + static_cast<std::ptrdiff_t>(next_));  // next_ is now the following queue's
    else
      ++next_;
  }
}

std::vector<Incoming> Inbox::drain() {
  std::vector<Incoming> all;
  take(total_, all);
  return all;
}

bool Bucket::take(IntakeClock::time_point now) {
  tokens_ = std::min(burst_, tokens_ + rate_ * std::chrono::duration<double>(now - at_).count());
  at_ = now;
  if (tokens_ < 1) return false;
  tokens_ -= 1;
  return true;
}

bool LogBudget::allow(IntakeClock::time_point now, std::uint64_t& held_back) {
  if (!lines_.take(now)) {
    ++held_back_;
    return false;
  }
  held_back = std::exchange(held_back_, 0);
  return true;
}

std::string RecentCommands::key(const char (&client_id)[65], std::uint64_t command_id) {
  std::string k(client_id, strnlen(client_id, sizeof client_id));
  k.append(reinterpret_cast<const char*>(&command_id), sizeof command_id);
  return k;
}

RecentCommands::Seen RecentCommands::note(const ladder_msg_Command& c) {
  std::string k = key(c.client_id, c.command_id);
  if (const auto it = seen_.find(k); it != seen_.end()) return it->second ? Seen::Answered : Seen::Pending;
  if (order_.size() >= kWindow) {
    seen_.erase(order_.front());
    order_.pop_front();
  }
  seen_.emplace(k, std::nullopt);
  order_.push_back(std::move(k));
  return Seen::New;
}

const Answer* RecentCommands::answer(const ladder_msg_Command& c) const {
  const auto it = seen_.find(key(c.client_id, c.command_id));
  return it != seen_.end() && it->second ? &*it->second : nullptr;
}

void RecentCommands::answered(const char (&client_id)[65], std::uint64_t command_id, Answer a) {
  if (const auto it = seen_.find(key(client_id, command_id)); it != seen_.end()) it->second = std::move(a);
}

void RecentCommands::forget(const ladder_msg_Command& c) {
  const std::string k = key(c.client_id, c.command_id);
  if (seen_.erase(k) == 0) return;
  // Usually the newest: the one just noted.
  const auto it = std::find(order_.rbegin(), order_.rend(), k);
  if (it != order_.rend()) order_.erase(std::next(it).base());
}

}  // namespace ladder::daemon
