#include <gtest/gtest.h>

#include "nursing_bed/core/fe/airbag_fe.h"

namespace nursing_bed {
namespace fe {

TEST(FeAirbag, Explore) {
  AirbagFeOptions o;
  o.geometry.elements_per_side = 12;
  AirbagFe bag(o);
  std::printf("nodes %d tris %d dt %g V0 %g top %g\n", bag.model().nodeCount(), bag.model().mesh().triangleCount(), bag.model().stableTimeStep(), bag.model().volume(), bag.model().plate().height_m);
  for (double p : {2e3, 5e3, 10e3, 15e3, 20e3, 25e3}) {
    auto q = bag.solveLoaded(p, 10.6);
    std::printf("p %.0f h %.2f mm V %.3g F %.2f it %d lmax %.3f wr %.2f inset %.2f %s\n", p, q.height_m*1e3, q.volume_m3, q.plate_force_n, q.iterations, q.max_stretch, q.wrinkled_fraction, q.rim_inset_m*1e3, q.message.c_str());
  }
}

}  // namespace fe
}  // namespace nursing_bed
