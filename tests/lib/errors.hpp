// SPDX-License-Identifier: LGPL-2.1-or-later
// The errors the readers of files raise, for the library tests.
#pragma once

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <future>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>

#include <gtest/gtest.h>

// The message of the std::runtime_error `f` throws ("" if it returns).
inline std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

// error_of(f), run on a thread of its own: one that does not return within `seconds` (a
// reader blocked on a FIFO, a hung parser) fails the test and ends the program, which
// could not stop it otherwise.
inline std::string error_within(const std::function<void()>& f, int seconds = 20) {
  auto done = std::make_shared<std::promise<std::string>>();
  std::future<std::string> result = done->get_future();
  std::thread([done, f] {
    try {
      done->set_value(error_of(f));
    } catch (...) {
      done->set_value("an exception other than std::runtime_error");
    }
  }).detach();
  if (result.wait_for(std::chrono::seconds(seconds)) != std::future_status::ready) {
    std::fprintf(stderr, "FATAL: the reader did not return within %d s\n", seconds);
    std::_Exit(1);
  }
  return result.get();
}

#define EXPECT_MENTIONS(message, needle) \
  EXPECT_NE(std::string(message).find(needle), std::string::npos) << "'" << (message) << "' lacks '" << (needle) << "'"
