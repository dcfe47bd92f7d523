// What an integration test names its server by: the test's own name, a DDS domain hashed from it, and a sim id
// from it and the pid (distinct from a killed run's server that discovery still lists until its lease ends), so that
// two tests running at once never meet.
#pragma once

#include <gtest/gtest.h>

#include <unistd.h>

#include <cctype>
#include <functional>
#include <string>

namespace ladder::test {

inline std::string test_name() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  return std::string(info->test_suite_name()) + "." + info->name();
}

inline int domain_for(const std::string& name) { return 1 + static_cast<int>(std::hash<std::string>{}(name) % 230); }

// At most 64 characters (a sim id's limit): the last 40 of the name, then the pid; letters, digits and '-'.
inline std::string sim_id_for(const std::string& name) {
  std::string id = name.substr(name.size() > 40 ? name.size() - 40 : 0) + "-" + std::to_string(getpid());
  for (char& ch : id)
    if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '-';
  return id;
}

}  // namespace ladder::test
