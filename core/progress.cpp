#include "core/progress.h"

#include "core/errors.h"

namespace organsmith {

void Progress::check_cancelled() const {
  if (cancelled()) throw Cancelled();
}

}  // namespace organsmith
