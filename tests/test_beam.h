// The project's beam model (data/models/beam), loaded once per test program, with a scratch cache folder beside
// it: the fixture of the continuation and local/global tests.
#pragma once
#include "lidef/model_check.h"
#include "test_support.h"

namespace lidef::test {

struct Beam {
  Beam() : model(load_model(project_data() + "/models/beam")) {}
  Model model;
  TempDir cache;
};
inline const Beam& beam() {
  static const Beam b;
  return b;
}

}  // namespace lidef::test
