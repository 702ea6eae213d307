// The simulator: a patient lying on the bed (core BodyModel) coupled to the airbag nodes. Each
// step it reads every cell's height from its AirbagState, rests the body on the cells, and
// publishes each cell's load on /airbag_loads, the interface pressure, the body's roll, rviz
// markers and tf frames of the body, and at ~tissue_load_rate_hz the tissue-load metrics per
// body region (core TissueLoadMeter). Optionally it is the clock (/clock, faster than real time)
// for tests. Same class as node (simulator_node) and nodelet (nursing_bed/SimulatorNodelet).
// Interface, model and coupling: doc/simulator.md.
#pragma once

#include <ros/ros.h>
#include <std_msgs/ColorRGBA.h>
#include <tf2_ros/transform_broadcaster.h>
#include <visualization_msgs/MarkerArray.h>

#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "nursing_bed/AirbagState.h"
#include "nursing_bed/RigTruth.h"
#include "nursing_bed/core/bed/body_model.h"
#include "nursing_bed/core/bed/tissue_load.h"
#include "nursing_bed/core/io/status.h"
#include "nursing_bed/ros/bed_layout.h"

namespace nursing_bed {

namespace sim_names {
constexpr const char* kBedMarkers = "/bed_markers";               // visualization_msgs/MarkerArray, bed_link
constexpr const char* kBodyRoll = "body_roll";                    // ~body_roll: std_msgs/Float64 [rad]
constexpr const char* kInterfacePressure = "interface_pressure";  // ~interface_pressure: nursing_bed/InterfacePressure
constexpr const char* kTissueLoad = "tissue_load";                // ~tissue_load: nursing_bed/TissueLoad
constexpr const char* kBodyLink = "body_link";                    // tf frame at the pelvis
}  // namespace sim_names

/// Everything the simulator reads from the parameter server, validated in one place.
struct SimulatorParams {
  PatientParams patient;                                ///< ~patient/...: mass_kg, height_m, head_clearance_m, ...
  std::string robot_description = "robot_description";  ///< ~robot_description_param
  std::string cells_ns = "/";                           ///< ~cells_ns: where the airbag_<r>_<c> nodes live
  /// ~truth_topic: a rig emulator's truth (nursing_bed/RigTruth); when set the body lies on the
  /// plates' true heights there, not on the heights the cells report (their estimates).
  std::string truth_topic;
  double rate_hz = 50.0;            ///< ~rate_hz: body solves and /airbag_loads per second [Hz]
  double load_filter_time_s = 0.1;  ///< ~load_filter_time_s: first-order filter on the published loads [s]
  double plate_weight_n = 0.6;      ///< ~plate_weight_n: added to every cell's load [N]
  double marker_rate_hz = 10.0;     ///< ~marker_rate_hz: /bed_markers and the body's tf [Hz]
  double cell_timeout_s = 1.0;      ///< ~cell_timeout_s: warn when a cell is silent this long [s]
  /// ~startup_wait_s: wait for every cell's first state until this long after the last new one [s]
  double startup_wait_s = 5.0;
  double lay_down_s = 2.0;           ///< ~lay_down_s: the body's loads reach the cells over this long [s]
  bool publish_clock = false;        ///< ~publish_clock: publish /clock (for use_sim_time runs)
  double clock_speed = 1.0;          ///< ~clock_speed: simulated seconds per wall second
  double clock_step_s = 0.005;       ///< ~clock_step_s: /clock increment [s]
  double tissue_load_rate_hz = 1.0;  ///< ~tissue_load_rate_hz: metrics sampled and published [Hz]
  TissueLoadParams tissue_load;      ///< ~tissue_load/...: threshold_pa, tolerance/... (config/tissue_load.yaml)

  /// Success when valid, else an error with every problem found.
  Status validate() const;
};

/// Colour of an interface pressure [mmHg]: grey without contact, green below the capillary
/// closing pressure (32 mmHg, darker to lighter), then a jump to yellow at 32 running to red at
/// 60 and dark red above.
std_msgs::ColorRGBA pressureColour(double mmhg);

class Simulator {
 public:
  /// Reads parameters, the bed layout and builds the body; throws std::runtime_error with a
  /// clear message when something is wrong.
  Simulator(ros::NodeHandle nh, ros::NodeHandle private_nh);
  ~Simulator();

  static SimulatorParams loadParams(const ros::NodeHandle& private_nh);

 private:
  /// The cells' states (and the truth, when given) in; loads, views and metrics out.
  void connectTopics();
  void onState(const AirbagState::ConstPtr& msg);
  void onTruth(const RigTruth::ConstPtr& msg);
  void onTimer(const ros::TimerEvent& event);
  void clockLoop();
  /// One step at time `now`: solve, filter, publish.
  void step(const ros::Time& now);
  // The steps of step(), in its order.
  /// The cells' last heights and reported loads, and how many never reported or went silent.
  struct CellSnapshot {
    std::vector<double> heights, reported;  // by cell id
    int unseen = 0, stale = 0;
  };
  CellSnapshot snapshotCells();
  /// False while waiting for every cell's first state (while cells still arrive, each new one
  /// gives the rest ~startup_wait_s more); warns of silent cells.
  bool coupled(const ros::Time& now, const CellSnapshot& cells);
  /// The body's cell loads through the first-order filter on /airbag_loads.
  void publishLoads(const BodyState& state, const std::vector<double>& reported, const ros::Time& now);
  /// Roll, interface pressure and, at ~marker_rate_hz, markers and tf.
  void publishViews(const BodyState& state, const std::vector<double>& heights, const ros::Time& now);
  /// Step timing for the debug log and the overrun warning.
  void recordStepTime(double took_s, int iterations);
  void publishPressure(const BodyState& state, const ros::Time& now);
  void publishMarkers(const BodyState& state, const std::vector<double>& heights, const ros::Time& now);
  void publishTf(const BodyState& state, const ros::Time& now);
  /// At ~tissue_load_rate_hz: the regions' loads on the last solve into the meter, published.
  void updateTissueLoad(const std::vector<double>& heights, const ros::Time& now);
  void publishTissueLoad(const ros::Time& now, double body_contact_area_m2);

  ros::NodeHandle nh_, private_nh_;
  SimulatorParams params_;
  BedLayout layout_;
  std::unique_ptr<BodyModel> body_;
  std::unique_ptr<TissueLoadMeter> tissue_;

  std::mutex state_mutex_;               // guards the cells' last states (callbacks on any thread)
  std::vector<double> heights_m_;        // by cell id
  std::vector<double> reported_load_n_;  // by cell id, the load the cell says it carries
  std::vector<double> truth_height_m_;   // by cell id, the rig emulator's truth (NaN: none)
  std::vector<ros::Time> last_seen_;     // by cell id (zero: never)

  std::mutex step_mutex_;                // one step at a time
  std::vector<double> filtered_load_n_;  // by cell id, plate included: what /airbag_loads says
  std::vector<double> handover_load_n_;  // by cell id, what the cells carried when the body was laid down
  bool started_ = false;
  int unseen_ = -1;  // cells without a first state at the last step (-1: none yet)
  ros::Time start_, last_arrival_, coupled_at_, last_step_, last_markers_, last_tissue_;
  double step_time_sum_s_ = 0.0, step_time_max_s_ = 0.0;
  long steps_ = 0;

  std::vector<ros::Subscriber> state_subs_;
  ros::Subscriber truth_sub_;
  ros::Publisher loads_pub_, roll_pub_, pressure_pub_, markers_pub_, clock_pub_, tissue_pub_;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_;
  ros::Timer timer_;
  std::thread clock_thread_;
  std::atomic<bool> stop_{false};
};

}  // namespace nursing_bed
