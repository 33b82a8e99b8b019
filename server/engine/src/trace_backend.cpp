// TraceBackend's default probe bounce (trace_backend.h): the probe gather, the running means on
// the host, the scatter.
#include "irradcast/engine/trace_backend.h"

#include <tbb/parallel_for.h>

#include <atomic>

namespace irradcast {

namespace {
std::atomic<std::uint64_t> next_probe_means_id{1};
}  // namespace

ProbeMeans::ProbeMeans() : id(next_probe_means_id.fetch_add(1)) {}

BounceResult TraceBackend::probe_bounce(const PassInput& in, const RadianceField& prev,
                                        float weight, ProbeMeans& means,
                                        std::vector<glm::vec3>& out) {
  BounceResult r;
  std::vector<glm::vec3> est;
  r.probes = gather_probes(in, prev, est);
  if (means.host.size() <= in.bounce) means.host.resize(in.bounce + 1);
  std::vector<glm::vec3>& mean = means.host[in.bounce];
  if (mean.size() != est.size()) mean.assign(est.size(), glm::vec3(0.0f));
  tbb::parallel_for(std::size_t(0), est.size(),
                    [&](std::size_t i) { mean[i] += (est[i] - mean[i]) * weight; });
  r.scatter = scatter(in, prev, mean, out);
  return r;
}

}  // namespace irradcast
