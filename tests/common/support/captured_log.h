// Routes spdlog's default logger to a sink that keeps what is logged, for a
// test's lifetime: the warnings (and worse) as text and as a count, so a test
// can assert what was said and how often.
#pragma once

#include <spdlog/sinks/base_sink.h>
#include <spdlog/spdlog.h>

#include <cstddef>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>

namespace vistream::testing {

class CapturedLog {
 public:
  CapturedLog() : sink_(std::make_shared<WarningSink>()), previous_(spdlog::default_logger()) {
    auto logger = std::make_shared<spdlog::logger>("captured", sink_);
    logger->set_level(spdlog::level::info);
    spdlog::set_default_logger(logger);
  }
  ~CapturedLog() { spdlog::set_default_logger(previous_); }
  CapturedLog(const CapturedLog&) = delete;
  CapturedLog& operator=(const CapturedLog&) = delete;

  // The warnings (and worse) logged so far, one per line (the first 1 MB).
  std::string warnings() const {
    std::lock_guard lock(sink_->textMutex);
    return sink_->text;
  }
  // How many warnings (and worse) were logged, all of them.
  size_t warningCount() const {
    std::lock_guard lock(sink_->textMutex);
    return sink_->count;
  }
  // How many of the kept warning lines contain `s`.
  size_t warningsContaining(const std::string& s) const {
    std::lock_guard lock(sink_->textMutex);
    size_t n = 0;
    for (size_t at = 0, end; at < sink_->text.size(); at = end + 1) {
      end = sink_->text.find('\n', at);
      if (end == std::string::npos) end = sink_->text.size();
      n += std::string_view(sink_->text).substr(at, end - at).find(s) != std::string_view::npos;
    }
    return n;
  }

 private:
  struct WarningSink : spdlog::sinks::base_sink<std::mutex> {
    mutable std::mutex textMutex;  // guards text and count
    std::string text;
    size_t count = 0;
    void sink_it_(const spdlog::details::log_msg& msg) override {
      if (msg.level < spdlog::level::warn) return;
      std::lock_guard lock(textMutex);
      ++count;
      if (text.size() < (1u << 20))
        text.append(msg.payload.data(), msg.payload.size()).append("\n");
    }
    void flush_() override {}
  };
  std::shared_ptr<WarningSink> sink_;
  std::shared_ptr<spdlog::logger> previous_;
};

}  // namespace vistream::testing
