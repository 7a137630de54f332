#pragma once
// Progress reporting and cancellation, passed into long stages (no global state).

#include <string_view>

namespace organsmith {

/// Receives progress from a long stage and tells it whether to stop. Implementations must be
/// safe to call from several threads (stages report from TBB workers).
class Progress {
 public:
  virtual ~Progress() = default;
  /// fraction in [0, 1] of the current task `what` (a short phrase, e.g. "reading slices").
  virtual void report(double fraction, std::string_view what) = 0;
  /// True when the caller wants the stage to stop; the stage then throws organsmith::Cancelled.
  virtual bool cancelled() const { return false; }
  /// Throws Cancelled when cancellation was requested.
  void check_cancelled() const;
};

/// Ignores progress and never cancels.
class NullProgress final : public Progress {
 public:
  void report(double, std::string_view) override {}
};

}  // namespace organsmith
