#include "lidef/explorer/counterexample.h"

#include <algorithm>
#include <cmath>

#include "lidef/number_format.h"

namespace lidef {
namespace {

std::string with_reason(const std::string& what, const std::string& reason) {
  return reason.empty() ? what : what + ": " + reason;
}

}  // namespace

CounterexampleVerdict counterexample_verdict(const CounterexampleChecks& c) {
  CounterexampleVerdict v;
  std::vector<std::string>& r = v.reasons;
  const Sigma3Minimum* m = c.minimum;
  if (!m || !m->strict)
    r.push_back("no strict interior minimum of sigma3");
  else if (!(m->sigma3 > 0))
    r.push_back("sigma3 = " + format_double(m->sigma3) + " <= 0 at the interior minimum");

  const BallCertificate* li = c.local_injectivity;
  if (!li)
    r.push_back("sigma3 > 0 on the ball not checked");
  else if (!li->certified || li->sphere_only || li->threshold < 0)
    r.push_back(with_reason("sigma3 > 0 on the ball not certified", li->reason));

  const BallCertificate* ba = c.boundary_above_minimum;
  if (!ba)
    r.push_back("sigma3 above the interior minimum on the boundary sphere not checked");
  else if (!ba->certified || !(m && ba->threshold >= m->sigma3))
    r.push_back(
        with_reason("sigma3 above the interior minimum on the boundary sphere not certified", ba->reason));

  const BoundaryInjectivity* bi = c.boundary_injectivity;
  if (!bi)
    r.push_back("injectivity on the boundary sphere not checked");
  else if (!bi->certified)
    r.push_back(with_reason("injectivity on the boundary sphere not certified", bi->reason));

  const BoundaryEmbedding* be = c.boundary_embedding;
  if (!be)
    r.push_back("boundary image embedding not checked");
  else if (!be->embedded)
    r.push_back("the triangulated boundary image is not embedded (" + std::to_string(be->intersecting_pairs) +
                " intersecting pairs)");

  v.verified = r.empty();
  return v;
}

double boundary_injectivity_threshold(const BallCertificate& local_injectivity,
                                      const Sigma3Minimum* minimum) {
  return 0.5 * std::min(local_injectivity.min_sigma3_center,
                        minimum && minimum->sigma3 > 0 ? minimum->sigma3 : INFINITY);
}

}  // namespace lidef
