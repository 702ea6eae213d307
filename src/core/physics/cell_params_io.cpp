#include "nursing_bed/core/physics/cell_params_io.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/package_path.h"

namespace nursing_bed {

std::string defaultCellParamsFile() { return findPackageFile("config/airbag_tpu_double_100.yaml"); }

namespace {

#define NB_FIELD(key, desc, expr) realField<CellParams>(key, desc, [](CellParams& p) -> double& { return expr; })

ParamTable<CellParams> makeFields() {
  return {
      NB_FIELD("gas/gas_constant_j_kg_k", "specific gas constant R of the fill gas [J/(kg K)]",
               p.gas.gas_constant_j_kg_k),
      NB_FIELD("gas/heat_capacity_ratio", "cp/cv of the fill gas [-]", p.gas.heat_capacity_ratio),
      NB_FIELD("ambient/pressure_pa", "ambient (atmospheric) pressure [Pa]", p.ambient_pressure_pa),
      NB_FIELD("ambient/temperature_k", "ambient temperature, also the initial gas temperature [K]",
               p.ambient_temperature_k),
      NB_FIELD("supply/temperature_k", "temperature of the supplied air [K]", p.supply_temperature_k),
      NB_FIELD("supply/pressure_pa", "pressure-reducing valve setting, gauge [Pa]", p.supply_pressure_pa),
      NB_FIELD("supply/regulator_time_constant_s", "first-order response time of the regulator outlet; 0 = ideal [s]",
               p.regulator_time_constant_s),
      NB_FIELD("valves/inlet_area_m2", "effective area Cd*A of the fully open inlet valve [m^2]", p.inlet_area_m2),
      NB_FIELD("valves/vent_area_m2", "effective area Cd*A of the fully open vent valve [m^2]", p.vent_area_m2),
      NB_FIELD("valves/leak_area_m2", "effective area of leakage through seams and film (paper eq. 17) [m^2]",
               p.leak_area_m2),
      NB_FIELD("valves/orifice_linear_band_pa", "pressure difference below which orifice flow is smoothed [Pa]",
               p.orifice_linear_band_pa),
      NB_FIELD("relief/cracking_pressure_pa", "gauge pressure where the relief valve starts to open [Pa]",
               p.relief_cracking_pressure_pa),
      NB_FIELD("relief/full_open_pressure_pa", "gauge pressure where the relief valve is fully open [Pa]",
               p.relief_full_open_pressure_pa),
      NB_FIELD("relief/sonic_conductance_m3_s_pa",
               "ISO 6358 sonic conductance C of the open relief valve; 0 = none [m^3/(s Pa)]",
               p.relief_sonic_conductance_m3_s_pa),
      NB_FIELD("relief/critical_pressure_ratio", "ISO 6358 critical pressure ratio b of the relief valve [-]",
               p.relief_critical_ratio),
      NB_FIELD("structure/face_side_m", "side of the square cell faces (deflated footprint) [m]",
               p.structure.face_side_m),
      NB_FIELD("structure/gusset_height_m", "unstretched side-gusset height of one chamber [m]",
               p.structure.gusset_height_m),
      integerField<CellParams>("structure/chambers", "stacked chambers sharing one gas volume [-]",
                               [](CellParams& p) -> int& { return p.structure.chambers; }),
      NB_FIELD("structure/film_thickness_m", "TPU film thickness [m]", p.structure.film_thickness_m),
      NB_FIELD("structure/dead_volume_m3", "gas volume of the flat cell: inlet fitting, tube stub, folds [m^3]",
               p.structure.dead_volume_m3),
      NB_FIELD(
          "structure/fold_fraction",
          "fraction of the dead volume in the flat films' folds, squeezed out by a plate pressing the flat cell [-]",
          p.structure.fold_fraction),
      NB_FIELD("structure/film_relaxation_time_s", "viscous time scale of the film shape [s]",
               p.structure.film_relaxation_time_s),
      NB_FIELD("structure/max_film_stretch", "largest film stretch trusted before rupture [-]",
               p.structure.max_film_stretch),
      NB_FIELD("bellows/area_m2", "plate area of a bellows (structure/type bellows) [m^2]", p.bellows.area_m2),
      NB_FIELD("bellows/compliance_m3_pa", "bellows compliance C = A^2/k, volume per gauge pressure [m^3/Pa]",
               p.bellows.compliance_m3_pa),
      NB_FIELD("bellows/dead_volume_m3", "bellows gas volume at zero plate travel (chamber, ports, tubing) [m^3]",
               p.bellows.dead_volume_m3),
      NB_FIELD("bellows/stroke_m", "largest plate travel of the bellows [m]", p.bellows.stroke_m),
      NB_FIELD("airway/volume_m3", "circuit gas volume between the meter/sensor and the airway resistor [m^3]",
               p.airway.volume_m3),
      NB_FIELD("airway/resistance_pa_s_m3", "airway resistor, linear term R1 of dp = R1 q + R2 q|q| [Pa s/m^3]",
               p.airway.resistance_pa_s_m3),
      NB_FIELD("airway/quadratic_resistance_pa_s2_m6", "airway resistor, quadratic term R2 [Pa s^2/m^6]",
               p.airway.quadratic_resistance_pa_s2_m6),
      NB_FIELD("material/c10_pa", "Yeoh constant C10 (paper eq. 7) [Pa]", p.structure.material.c10_pa),
      NB_FIELD("material/c20_pa", "Yeoh constant C20 [Pa]", p.structure.material.c20_pa),
      NB_FIELD("material/c30_pa", "Yeoh constant C30 [Pa]", p.structure.material.c30_pa),
      NB_FIELD("plate/mass_kg", "mass of the loading plate alone [kg]", p.plate_mass_kg),
      NB_FIELD("plate/damping_n_s_m", "viscous damping of the plate guide [N s/m]", p.plate_damping_n_s_m),
      NB_FIELD("plate/bed_contact_stiffness_n_m", "stiffness of the film stack under a bottomed plate [N/m]",
               p.bed_contact_stiffness_n_m),
      NB_FIELD("plate/bed_contact_damping_s_m",
               "Hunt-Crossley damping alpha of that contact, force k x (1 + alpha dx/dt) [s/m]",
               p.bed_contact_damping_s_m),
      NB_FIELD("integration/time_step_s", "default integration step, the largest of step() [s]", p.time_step_s),
      NB_FIELD("integration/max_time_step_s", "longest step advance() takes where the error estimate allows it [s]",
               p.max_time_step_s),
      integerField<CellParams>("integration/jacobian_refresh_steps", "accepted steps between Jacobian updates [-]",
                               [](CellParams& p) -> int& { return p.jacobian_refresh_steps; }),
      NB_FIELD("integration/relative_tolerance", "local error tolerance of the sub-steps [-]", p.relative_tolerance),
  };
}
#undef NB_FIELD

}  // namespace

const ParamTable<CellParams>& cellParamFields() {
  static const ParamTable<CellParams> fields = makeFields();
  return fields;
}

CellParams parseCellParamsYaml(const std::string& yaml_text, const std::string& source, const CellParams& defaults) {
  CellParams params = defaults;
  FlatParams flat = flattenYamlText(yaml_text, source);
  applyStructureSelection(&flat, "", &params);
  applyFlatParams(flat, source, cellParamFields(), &params);
  const std::string error = params.validate();
  if (!error.empty()) throw std::runtime_error(source + ": invalid parameters: " + error);
  return params;
}

CellParams loadCellParamsYaml(const std::string& path, const CellParams& defaults) {
  CellParams params = defaults;
  FlatParams flat = flattenYamlFile(path);
  applyStructureSelection(&flat, std::filesystem::path(path).parent_path().string(), &params);
  applyFlatParams(flat, path, cellParamFields(), &params);
  const std::string error = params.validate();
  if (!error.empty()) throw std::runtime_error(path + ": invalid parameters: " + error);
  return params;
}

void applyStructureSelection(FlatParams* flat, const std::string& base_dir, CellParams* params,
                             const std::string& prefix) {
  const auto type = flat->find(prefix + "structure/type");
  if (type != flat->end()) {
    params->structure_type = type->second.text;
    flat->erase(type);
  }
  const auto file = flat->find(prefix + "structure/table_file");
  if (file != flat->end()) {
    const std::filesystem::path path(file->second.text);
    params->structure_table_file =
        path.is_relative() && !base_dir.empty() ? (std::filesystem::path(base_dir) / path).string() : path.string();
    flat->erase(file);
  }
}

std::string cellParamsToYaml(const CellParams& params) { return paramsToYaml(params, cellParamFields()); }

}  // namespace nursing_bed
