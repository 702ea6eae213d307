// The paper's eq. 24 curve treated as measured data (x read as bar, doc/paper_targets.md): a
// quasi-static h(p) for the paper's 10.4 N load. Where our model departs from it, and what the
// candidate effects of the gap diagnosis can say about it. `gap eq24` prints it;
// doc/gap_diagnosis.md discusses it.
#pragma once

#include <string>
#include <vector>

#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {

// size: a plain record of the eq. 24 study's figures, one field per reported number
struct PaperCurveStudy {
  double load_n = 0.0;
  double inflow_kg_s = 0.0;            ///< the slow constant inflow of the quasi-static runs
  std::vector<double> pressure_pa;     ///< the comparison grid (10-28 kPa)
  std::vector<double> paper_height_m;  ///< eq. 24 there
  std::vector<double> model_height_m;  ///< the nominal model's rising h(p) there (NaN: not reached)
  double nominal_rms_m = 0.0;          ///< model vs eq. 24
  struct Band {
    double p_lo_pa, p_hi_pa, mean_difference_m;  ///< model - paper, mean over the band
  };
  std::vector<Band> bands;
  struct Candidate {
    std::string effect;      ///< canonical name
    std::string parameters;  ///< as described (mid plausible values)
    double rms_m = 0.0;      ///< rising h(p) with it vs eq. 24
  };
  std::vector<Candidate> candidates;                ///< each candidate at a mid-plausible magnitude
  double dynamic_mass_kg = 0.0;                     ///< the paper-shaped inflation's gas
  double dynamic_nominal_rms_m = 0.0;               ///< its rising h(p) vs eq. 24, nominal model
  double line_volume_m3 = 0.0, line_area_m2 = 0.0;  ///< supply line fitted to eq. 24 (area only)
  double line_rms_m = 0.0;                          ///< what is left then
  std::vector<double> line_height_m;                ///< that model's rising h at the grid pressures
  double friction_needed_n = 0.0;                   ///< guide friction that best shifts the model onto eq. 24
  double friction_rms_m = 0.0;                      ///< what is left then
};

/// Quasi-static inflations (a constant inflow that takes ~300 s to 28 kPa) of the nominal model
/// and of each candidate at a mid-plausible magnitude, compared with eq. 24 over 10-28 kPa; plus
/// the friction (an extra load while rising) that fits eq. 24 best.
PaperCurveStudy studyPaperEq24(const CellParams& params);
std::string paperStudyMarkdown(const PaperCurveStudy& study);

}  // namespace nursing_bed
