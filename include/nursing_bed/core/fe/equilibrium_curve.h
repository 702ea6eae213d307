// The loaded bag's equilibria at one pressure as a plate force-height curve (ROS-free). The
// FE bag inflated by pressure steps under a spread of loads (the h(p) procedure) passes
// through one state per load and pressure; between two loads' plate heights the force is
// interpolated. fe_airbag's "equilibria" table takes these states where they exist: the bag
// held at (h, p) may sit in another fold than the loaded bag that passed there (doc/fe_membrane.md).
#pragma once

#include <string>
#include <vector>

namespace nursing_bed {
namespace fe {

/// One loaded equilibrium: the load [N], where its plate rests [m], the gas volume [m^3].
struct LoadedState {
  double load_n = 0.0;
  double height_m = 0.0;
  double volume_m3 = 0.0;
};

/// The states at one pressure as a one-valued curve, from the lightest load (the highest plate)
/// down: a heavier load is kept only where its plate rests lower than the last one kept (a load
/// whose plate has not snapped up while a lighter one's has would make F(h) two-valued); each
/// one left out is named in `*left_out` (if given).
std::vector<LoadedState> equilibriumCurve(std::vector<LoadedState> states,
                                          std::vector<std::string>* left_out = nullptr);

/// Plate force [N] and volume [m^3] at height h on the curve (linear in h between its loads);
/// false outside its heights (above the lightest load's plate, below the heaviest's).
bool onEquilibriumCurve(const std::vector<LoadedState>& curve, double height_m, double* force_n, double* volume_m3);

}  // namespace fe
}  // namespace nursing_bed
