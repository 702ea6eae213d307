#include "nursing_bed/ros/simulator.h"

#include <XmlRpcValue.h>
#include <geometry_msgs/TransformStamped.h>
#include <rosgraph_msgs/Clock.h>
#include <std_msgs/Float64.h>
#include <std_msgs/Float64MultiArray.h>
#include <tf2/LinearMath/Quaternion.h>
#include <tf2/LinearMath/Transform.h>

#include <algorithm>
#include <boost/make_shared.hpp>
#include <cmath>
#include <limits>
#include <set>
#include <sstream>

#include "nursing_bed/InterfacePressure.h"
#include "nursing_bed/TissueLoad.h"
#include "nursing_bed/core/io/errors.h"
#include "nursing_bed/core/physics/units.h"
#include "nursing_bed/ros/names.h"
#include "nursing_bed/ros/ros_params.h"

namespace nursing_bed {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// The ~patient/ keys (PatientParams fields); anything else there is a typo and refused.
const std::set<std::string> kPatientKeys = {"mass_kg",          "height_m",
                                            "head_clearance_m", "tissue_stiffness_pa_m",
                                            "lateral_offset_m", "contact_resolution_m",
                                            "smooth_cover",     "max_roll_rad",
                                            "articulated",      "joint_stiffness_n_m"};

/// Reads `key` when it is set; throws naming it when it has the wrong type.
template <typename T>
void readParam(const ros::NodeHandle& nh, const std::string& key, T* value) {
  if (!nh.hasParam(key)) return;
  if (!nh.getParam(key, *value))
    throw std::runtime_error("simulator: parameter " + nh.resolveName(key) + " has the wrong type");
}

std_msgs::ColorRGBA rgba(double r, double g, double b, double a = 1.0) {
  std_msgs::ColorRGBA c;
  c.r = static_cast<float>(r);
  c.g = static_cast<float>(g);
  c.b = static_cast<float>(b);
  c.a = static_cast<float>(a);
  return c;
}

std_msgs::ColorRGBA mix(const std_msgs::ColorRGBA& a, const std_msgs::ColorRGBA& b, double f) {
  f = std::clamp(f, 0.0, 1.0);
  return rgba(a.r + f * (b.r - a.r), a.g + f * (b.g - a.g), a.b + f * (b.b - a.b), a.a + f * (b.a - a.a));
}

geometry_msgs::Quaternion toMsg(const tf2::Quaternion& q) {
  geometry_msgs::Quaternion m;
  m.x = q.x();
  m.y = q.y();
  m.z = q.z();
  m.w = q.w();
  return m;
}

/// A segment's frame: at the centre of its cross-section (depth/2 above the underside apex,
/// along the rolled normal), x along the body towards the head, z out of the back.
tf2::Transform segmentFrame(const SegmentPose& s) {
  tf2::Quaternion q;
  q.setRPY(s.roll_rad, 0.0, 0.0);
  const double half = 0.5 * s.depth_m;
  return tf2::Transform(
      q, tf2::Vector3(s.x_c_m, s.y_c_m - half * std::sin(s.roll_rad), s.z_m + half * std::cos(s.roll_rad)));
}

/// A marker of the bed's markers array: stamped in bed_link, added, expiring soon after the
/// simulator stops.
visualization_msgs::Marker baseMarker(const std::string& ns, int id, int type, const ros::Time& now) {
  visualization_msgs::Marker m;
  m.header.stamp = now;
  m.header.frame_id = BedLayout::kBedLink;
  m.ns = ns;
  m.id = id;
  m.type = type;
  m.action = visualization_msgs::Marker::ADD;
  m.pose.orientation.w = 1.0;
  m.lifetime = ros::Duration(2.0);  // gone soon after the simulator stops
  return m;
}

/// The body's colour: translucent, so that the pressure under it shows.
std_msgs::ColorRGBA skinColour() { return rgba(0.95, 0.78, 0.66, 0.55); }

/// Turns a cylinder's axis (z) along the body (x).
tf2::Quaternion cylinderAlongBody() {
  tf2::Quaternion along_x;
  along_x.setRPY(0.0, kPi / 2.0, 0.0);
  return along_x;
}

/// Plates coloured by the highest point pressure over each cell's face, drawn just above the
/// URDF's plates (top 1 mm above the cell height) so that they win the depth test.
visualization_msgs::Marker plateMarker(const BedLayout& layout, const BodyState& s, const std::vector<double>& heights,
                                       const ros::Time& now) {
  const double pitch = layout.pitchM();
  visualization_msgs::Marker plates = baseMarker("plates", 0, visualization_msgs::Marker::CUBE_LIST, now);
  plates.scale.x = plates.scale.y = 0.96 * pitch;
  plates.scale.z = 0.006;
  for (const CellLayout& c : layout.cells()) {
    geometry_msgs::Point p;
    p.x = c.x_m;
    p.y = c.y_m;
    p.z = heights[c.id] + 0.001 - 0.5 * plates.scale.z;
    plates.points.push_back(p);
    plates.colors.push_back(pressureColour(paToMmHg(s.cell_peak_pressure_pa[c.id])));
  }
  return plates;
}

/// Body segments: limbs and trunk as cylinders along the body, head as an ellipsoid, feet as
/// boxes standing up from the heel.
void addSegmentMarkers(const BodyState& s, const ros::Time& now, std::vector<visualization_msgs::Marker>* out) {
  const tf2::Quaternion along_x = cylinderAlongBody();
  for (std::size_t i = 0; i < s.segments.size(); ++i) {
    const SegmentPose& seg = s.segments[i];
    const bool head = seg.name == "head_neck";
    const bool foot = seg.name.size() > 5 && seg.name.compare(seg.name.size() - 5, 5, "_foot") == 0;
    visualization_msgs::Marker m =
        baseMarker("body", static_cast<int>(i),
                   head ? visualization_msgs::Marker::SPHERE
                        : (foot ? visualization_msgs::Marker::CUBE : visualization_msgs::Marker::CYLINDER),
                   now);
    const tf2::Transform frame = segmentFrame(seg);
    m.pose.position.x = frame.getOrigin().x();
    m.pose.position.y = frame.getOrigin().y();
    m.pose.position.z = frame.getOrigin().z();
    if (head || foot) {
      m.pose.orientation = toMsg(frame.getRotation());
      m.scale.x = seg.footprint_length_m;
      m.scale.y = seg.width_m;
      m.scale.z = seg.depth_m;
    } else {
      m.pose.orientation = toMsg(frame.getRotation() * along_x);
      m.scale.x = seg.depth_m;  // along the rolled normal
      m.scale.y = seg.width_m;
      m.scale.z = seg.footprint_length_m;
    }
    m.color = skinColour();
    out->push_back(m);
  }
}

/// The neck, between the head and the thorax (touches nothing, drawn for the picture).
void addNeckMarker(const BodyState& s, const ros::Time& now, std::vector<visualization_msgs::Marker>* out) {
  const int head_i = BodyModel::segmentIndex("head_neck"), thorax_i = BodyModel::segmentIndex("thorax");
  if (head_i < 0 || thorax_i < 0) return;
  const SegmentPose& h = s.segments[head_i];
  const SegmentPose& t = s.segments[thorax_i];
  const tf2::Transform fh = segmentFrame(h), ft = segmentFrame(t);
  const double x0 = h.x_c_m - 0.5 * h.footprint_length_m, x1 = t.x_c_m + 0.5 * t.footprint_length_m;
  visualization_msgs::Marker neck =
      baseMarker("body", static_cast<int>(s.segments.size()), visualization_msgs::Marker::CYLINDER, now);
  neck.pose.position.x = 0.5 * (x0 + x1) + 0.01;
  neck.pose.position.y = 0.5 * (fh.getOrigin().y() + ft.getOrigin().y());
  neck.pose.position.z = 0.5 * (fh.getOrigin().z() + ft.getOrigin().z());
  neck.pose.orientation = toMsg(ft.getRotation() * cylinderAlongBody());
  neck.scale.x = neck.scale.y = 0.6 * h.width_m;
  neck.scale.z = std::max(0.02, x0 - x1 + 0.04);
  neck.color = skinColour();
  out->push_back(neck);
}

/// Peak labels over the head, the pelvis and the heels.
void addPeakLabels(const BodyState& s, const ros::Time& now, std::vector<visualization_msgs::Marker>* out) {
  auto label = [&](int id, const std::string& text, double x, double y, double z) {
    visualization_msgs::Marker m = baseMarker("labels", id, visualization_msgs::Marker::TEXT_VIEW_FACING, now);
    m.pose.position.x = x;
    m.pose.position.y = y;
    m.pose.position.z = z;
    m.scale.z = 0.05;
    m.color = rgba(1.0, 1.0, 1.0, 0.95);
    m.text = text;
    out->push_back(m);
  };
  auto mmhg = [](double pa) {
    std::ostringstream o;
    o.precision(0);
    o << std::fixed << paToMmHg(pa) << " mmHg";
    return o.str();
  };
  const SegmentPose& pelvis = s.segments[BodyModel::segmentIndex("pelvis")];
  const SegmentPose& head = s.segments[BodyModel::segmentIndex("head_neck")];
  const SegmentPose& foot = s.segments[BodyModel::segmentIndex("left_foot")];
  label(0, "occiput " + mmhg(s.peak_pressure_pa.occiput), head.x_c_m, head.y_c_m, head.z_m + head.depth_m + 0.06);
  label(1, "sacrum " + mmhg(s.peak_pressure_pa.sacrum), pelvis.x_c_m, pelvis.y_c_m, pelvis.z_m + pelvis.depth_m + 0.06);
  label(2, "heels " + mmhg(s.peak_pressure_pa.heels), foot.x_c_m, 0.0, foot.z_m + foot.depth_m + 0.06);
}

}  // namespace

std_msgs::ColorRGBA pressureColour(double mmhg) {
  if (!(mmhg >= 1.0)) return rgba(0.42, 0.45, 0.50);  // no contact (or NaN)
  if (mmhg < 32.0) return mix(rgba(0.05, 0.38, 0.14), rgba(0.50, 0.88, 0.28), mmhg / 32.0);
  if (mmhg < 60.0) return mix(rgba(1.0, 0.92, 0.0), rgba(0.92, 0.05, 0.03), (mmhg - 32.0) / 28.0);
  return mix(rgba(0.92, 0.05, 0.03), rgba(0.45, 0.0, 0.12), (mmhg - 60.0) / 40.0);
}

Status SimulatorParams::validate() const {
  ErrorList errors;
  errors.addNested(patient.validate(), "~patient/: ");
  errors.addIf(!(rate_hz > 0.0 && rate_hz <= 500.0), "~rate_hz must lie in (0, 500]");
  errors.addIf(!(load_filter_time_s >= 0.0 && load_filter_time_s <= 10.0), "~load_filter_time_s must lie in [0, 10] s");
  errors.addIf(!(plate_weight_n >= 0.0 && std::isfinite(plate_weight_n)), "~plate_weight_n must be >= 0 N");
  errors.addIf(!(marker_rate_hz > 0.0 && marker_rate_hz <= rate_hz), "~marker_rate_hz must lie in (0, rate_hz]");
  errors.addIf(!(tissue_load_rate_hz > 0.0 && tissue_load_rate_hz <= rate_hz),
               "~tissue_load_rate_hz must lie in (0, rate_hz]");
  errors.addNested(tissue_load.validate(), "~tissue_load/: ");
  errors.addIf(!(cell_timeout_s > 0.0), "~cell_timeout_s must be positive");
  errors.addIf(!(startup_wait_s >= 0.0 && startup_wait_s <= 600.0), "~startup_wait_s must lie in [0, 600] s");
  errors.addIf(!(lay_down_s >= 0.0 && lay_down_s <= 60.0), "~lay_down_s must lie in [0, 60] s");
  errors.addIf(!(clock_speed > 0.0 && clock_speed <= 100.0), "~clock_speed must lie in (0, 100]");
  errors.addIf(!(clock_step_s > 0.0 && clock_step_s <= 1.0 / rate_hz), "~clock_step_s must lie in (0, 1 / rate_hz]");
  return errors.status();
}

SimulatorParams Simulator::loadParams(const ros::NodeHandle& pnh) {
  SimulatorParams p;
  readParam(pnh, "robot_description_param", &p.robot_description);
  readParam(pnh, "cells_ns", &p.cells_ns);
  readParam(pnh, "truth_topic", &p.truth_topic);
  readParam(pnh, "rate_hz", &p.rate_hz);
  readParam(pnh, "load_filter_time_s", &p.load_filter_time_s);
  readParam(pnh, "plate_weight_n", &p.plate_weight_n);
  readParam(pnh, "marker_rate_hz", &p.marker_rate_hz);
  readParam(pnh, "cell_timeout_s", &p.cell_timeout_s);
  readParam(pnh, "startup_wait_s", &p.startup_wait_s);
  readParam(pnh, "lay_down_s", &p.lay_down_s);
  readParam(pnh, "publish_clock", &p.publish_clock);
  readParam(pnh, "clock_speed", &p.clock_speed);
  readParam(pnh, "clock_step_s", &p.clock_step_s);
  readParam(pnh, "tissue_load_rate_hz", &p.tissue_load_rate_hz);
  try {
    applyFlatParams(flattenRosParams(pnh, "tissue_load"), "parameters " + pnh.resolveName("tissue_load"),
                    tissueLoadParamFields(), &p.tissue_load);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(std::string("simulator: ") + e.what());
  }
  XmlRpc::XmlRpcValue patient;
  if (pnh.getParam("patient", patient)) {
    if (patient.getType() != XmlRpc::XmlRpcValue::TypeStruct)
      throw std::runtime_error("simulator: " + pnh.resolveName("patient") + " must be a map of parameters");
    for (auto it = patient.begin(); it != patient.end(); ++it) {
      if (kPatientKeys.count(it->first)) continue;
      std::string known;
      for (const std::string& k : kPatientKeys) known += (known.empty() ? "" : ", ") + k;
      throw std::runtime_error("simulator: unknown parameter " + pnh.resolveName("patient/" + it->first) +
                               " (known: " + known + ")");
    }
  }
  readParam(pnh, "patient/mass_kg", &p.patient.mass_kg);
  readParam(pnh, "patient/height_m", &p.patient.height_m);
  readParam(pnh, "patient/head_clearance_m", &p.patient.head_clearance_m);
  readParam(pnh, "patient/tissue_stiffness_pa_m", &p.patient.tissue_stiffness_pa_m);
  readParam(pnh, "patient/lateral_offset_m", &p.patient.lateral_offset_m);
  readParam(pnh, "patient/contact_resolution_m", &p.patient.contact_resolution_m);
  readParam(pnh, "patient/smooth_cover", &p.patient.smooth_cover);
  readParam(pnh, "patient/max_roll_rad", &p.patient.max_roll_rad);
  readParam(pnh, "patient/articulated", &p.patient.articulated);
  readParam(pnh, "patient/joint_stiffness_n_m", &p.patient.joint_stiffness_n_m);
  return p;
}

Simulator::Simulator(ros::NodeHandle nh, ros::NodeHandle private_nh) : nh_(nh), private_nh_(private_nh) {
  params_ = loadParams(private_nh_);
  const Status valid = params_.validate();
  if (!valid.ok()) throw std::runtime_error("simulator: " + valid.message());
  std::string urdf;
  if (!nh_.getParam(params_.robot_description, urdf))
    throw std::runtime_error("simulator: no bed description on parameter '" +
                             nh_.resolveName(params_.robot_description) +
                             "' (load it from scripts/make_bed_urdf.py, as sim.launch does)");
  layout_ = BedLayout::fromUrdf(urdf);
  BedGrid grid;
  grid.rows = layout_.rows();
  grid.cols = layout_.cols();
  grid.pitch_m = layout_.pitchM();
  grid.min_height_m = layout_.cells().front().min_height_m;
  grid.max_height_m = layout_.cells().front().max_height_m;
  for (const CellLayout& c : layout_.cells()) {
    if (std::abs(c.x_m - grid.x(c.row)) > 1e-3 || std::abs(c.y_m - grid.y(c.col)) > 1e-3) {
      std::ostringstream m;
      m << "simulator: cell " << c.link_name << " is at (" << c.x_m << ", " << c.y_m
        << ") m in the URDF, not at the grid's (" << grid.x(c.row) << ", " << grid.y(c.col)
        << ") m: the bed is not centred on bed_link";
      throw std::runtime_error(m.str());
    }
  }
  try {
    body_ = std::make_unique<BodyModel>(params_.patient, grid);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(std::string("simulator: ") + e.what() +
                             " (no patient on this bed: start sim.launch with simulator:=false)");
  }
  // Loop gain of the coupling (doc/simulator.md): a fully covered cell's tissue stiffness
  // against the softest cell (~1000 N/m, held gas at 120 mm under a light load).
  const double tissue_n_m = params_.patient.tissue_stiffness_pa_m * grid.cellAreaM2();
  if (tissue_n_m > 3000.0)
    ROS_WARN(
        "simulator: ~patient/tissue_stiffness_pa_m %g Pa/m makes a cell's tissue stiffness %.0f N/m, several times "
        "the softest cells' (~1000 N/m): the load loop may ring; keep ~load_filter_time_s >= 0.1 s",
        params_.patient.tissue_stiffness_pa_m, tissue_n_m);
  if (params_.load_filter_time_s < 0.5 / params_.rate_hz)
    ROS_WARN(
        "simulator: ~load_filter_time_s %g s is shorter than half a step: the loads are not under-relaxed and the "
        "loop through the cells may ring (doc/simulator.md)",
        params_.load_filter_time_s);

  tissue_ = std::make_unique<TissueLoadMeter>(params_.tissue_load, defaultTissueRegions());
  const std::size_t n = layout_.cells().size();
  heights_m_.assign(n, grid.min_height_m);
  reported_load_n_.assign(n, kNaN);
  truth_height_m_.assign(n, kNaN);
  last_seen_.assign(n, ros::Time());
  connectTopics();

  const std::vector<int> rows = body_->footprintRows();
  ROS_INFO("simulator: %.1f kg, %.2f m patient on %s; body over rows %d..%d (trunk %d..%d), k_w %.3g Pa/m, %s",
           params_.patient.mass_kg, params_.patient.height_m, layout_.describe().c_str(), rows.front(), rows.back(),
           body_->trunkRows().front(), body_->trunkRows().back(), params_.patient.tissue_stiffness_pa_m,
           params_.publish_clock ? "publishing /clock" : "following ROS time");
  if (params_.publish_clock) {
    bool sim_time = false;
    ros::param::get("/use_sim_time", sim_time);
    if (!sim_time)
      ROS_WARN(
          "simulator: ~publish_clock is true but /use_sim_time is not: the cells follow the wall clock, not this "
          "/clock (set /use_sim_time true before any node starts)");
    clock_pub_ = nh_.advertise<rosgraph_msgs::Clock>("/clock", 10);
    clock_thread_ = std::thread(&Simulator::clockLoop, this);
  } else {
    timer_ = nh_.createTimer(ros::Duration(1.0 / params_.rate_hz), &Simulator::onTimer, this);
  }
}

Simulator::~Simulator() {
  stop_ = true;
  timer_.stop();
  if (clock_thread_.joinable()) clock_thread_.join();
}

void Simulator::connectTopics() {
  std::string prefix = params_.cells_ns;
  if (prefix.empty() || prefix.back() != '/') prefix += '/';
  for (const CellLayout& c : layout_.cells())
    state_subs_.push_back(nh_.subscribe(prefix + names::airbagName(c.row, c.col) + "/" + names::kState, 2,
                                        &Simulator::onState, this, ros::TransportHints().tcpNoDelay()));
  // A real body lies on the plates where they are, whatever the cells believe: with a rig
  // emulator's truth the estimates' errors do not feed back into the loads.
  if (!params_.truth_topic.empty())
    truth_sub_ = nh_.subscribe(params_.truth_topic, 2, &Simulator::onTruth, this, ros::TransportHints().tcpNoDelay());
  loads_pub_ = nh_.advertise<std_msgs::Float64MultiArray>(names::kCellLoads, 2);
  roll_pub_ = private_nh_.advertise<std_msgs::Float64>(sim_names::kBodyRoll, 2);
  pressure_pub_ = private_nh_.advertise<InterfacePressure>(sim_names::kInterfacePressure, 2);
  markers_pub_ = nh_.advertise<visualization_msgs::MarkerArray>(sim_names::kBedMarkers, 2);
  tissue_pub_ = private_nh_.advertise<TissueLoad>(sim_names::kTissueLoad, 2);
  tf_ = std::make_unique<tf2_ros::TransformBroadcaster>();
}

void Simulator::onState(const AirbagState::ConstPtr& msg) {
  if (msg->cell_id >= heights_m_.size() || !std::isfinite(msg->height_m)) return;
  std::lock_guard<std::mutex> lock(state_mutex_);
  if (params_.truth_topic.empty() || !std::isfinite(truth_height_m_[msg->cell_id]))
    heights_m_[msg->cell_id] = msg->height_m;
  reported_load_n_[msg->cell_id] = msg->external_load_n;
  last_seen_[msg->cell_id] = ros::Time::now();
}

void Simulator::onTruth(const RigTruth::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(state_mutex_);
  const std::size_t n = std::min(msg->height_m.size(), heights_m_.size());
  for (std::size_t id = 0; id < n; ++id) {
    truth_height_m_[id] = msg->height_m[id];
    if (std::isfinite(msg->height_m[id])) heights_m_[id] = msg->height_m[id];
  }
}

void Simulator::onTimer(const ros::TimerEvent&) { step(ros::Time::now()); }

void Simulator::clockLoop() {
  // Simulated time starts at 0 (the cells' CellTicker waits for a valid time) and advances by
  // clock_step_s every clock_step_s / clock_speed of wall time; the body steps every
  // 1 / rate_hz of simulated time. When the machine cannot keep up, simulated time slows
  // down instead of jumping (the cells would see one long step).
  const double period = 1.0 / params_.rate_hz;
  double sim = 0.0, next_step = 0.0;
  ros::WallTime wall_next = ros::WallTime::now();
  while (!stop_ && ros::ok()) {
    sim += params_.clock_step_s;
    rosgraph_msgs::Clock clock;
    clock.clock = ros::Time(sim);
    clock_pub_.publish(clock);
    if (sim + 1e-9 >= next_step) {
      step(ros::Time(sim));
      next_step += period;
      if (next_step <= sim) next_step = sim + period;
    }
    wall_next += ros::WallDuration(params_.clock_step_s / params_.clock_speed);
    const ros::WallTime wall_now = ros::WallTime::now();
    if (wall_next > wall_now) {
      (wall_next - wall_now).sleep();
    } else if ((wall_now - wall_next).toSec() > 0.2) {
      ROS_WARN_THROTTLE(10.0, "simulator: /clock runs slower than ~clock_speed %g: the machine cannot keep up",
                        params_.clock_speed);
      wall_next = wall_now;
    }
  }
}

Simulator::CellSnapshot Simulator::snapshotCells() {
  CellSnapshot snap;
  std::lock_guard<std::mutex> lock(state_mutex_);
  snap.heights = heights_m_;
  snap.reported = reported_load_n_;
  const ros::Time ros_now = ros::Time::now();
  for (const ros::Time& seen : last_seen_) {
    if (seen.isZero()) ++snap.unseen;
    else if ((ros_now - seen).toSec() > params_.cell_timeout_s) ++snap.stale;
  }
  return snap;
}

bool Simulator::coupled(const ros::Time& now, const CellSnapshot& cells) {
  if (!started_) {
    if (start_.isZero()) start_ = last_arrival_ = now;
    // Cells that come up over a fieldbus arrive over seconds: wait while they still do, so the
    // body is never laid on a cell only because it is late (it would rest on it at the floor).
    if (cells.unseen != unseen_) last_arrival_ = now;
    unseen_ = cells.unseen;
    if (cells.unseen > 0 && (now - last_arrival_).toSec() < params_.startup_wait_s) return false;
    if (cells.unseen > 0)
      ROS_WARN("simulator: %d of %zu cells never reported; the body rests on them at %.3f m", cells.unseen,
               cells.heights.size(), body_->grid().min_height_m);
    ROS_INFO("simulator: laying the body on the cells over %g s (loads through %s)", params_.lay_down_s,
             names::kCellLoads);
    started_ = true;
    coupled_at_ = now;
  }
  if (cells.stale > 0)
    ROS_WARN_THROTTLE(10.0, "simulator: %d cells silent for more than %g s; the body rests on their last heights",
                      cells.stale, params_.cell_timeout_s);
  return true;
}

void Simulator::publishLoads(const BodyState& state, const std::vector<double>& reported, const ros::Time& now) {
  const std::size_t n = reported.size();
  // Loads under-relaxed by a first-order filter (the loop gain per step stays below 1; see
  // doc/simulator.md, "Coupling"). It starts from what the cells carry now, so the handover
  // from the launch's uniform load is smooth.
  if (filtered_load_n_.empty()) {
    filtered_load_n_.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      filtered_load_n_[i] = std::isfinite(reported[i]) ? reported[i] : params_.plate_weight_n + state.cell_load_n[i];
    handover_load_n_ = filtered_load_n_;
    last_step_ = now;
  }
  const double dt = std::clamp((now - last_step_).toSec(), 0.0, 1.0);
  last_step_ = now;
  const double alpha = params_.load_filter_time_s > 0.0 ? 1.0 - std::exp(-dt / params_.load_filter_time_s) : 1.0;
  // A patient is laid down, not dropped: the body's share of the load rises as a smoothstep
  // over lay_down_s (peak rate 1.5 x the change / lay_down_s), as a nurse lowers a patient.
  const double x =
      params_.lay_down_s > 0.0 ? std::clamp((now - coupled_at_).toSec() / params_.lay_down_s, 0.0, 1.0) : 1.0;
  const double laid = x * x * (3.0 - 2.0 * x);
  const boost::shared_ptr<std_msgs::Float64MultiArray> loads = boost::make_shared<std_msgs::Float64MultiArray>();
  loads->layout.dim.resize(1);
  loads->layout.dim[0].label = "cell_id";
  loads->layout.dim[0].size = static_cast<uint32_t>(n);
  loads->layout.dim[0].stride = static_cast<uint32_t>(n);
  loads->data.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double target =
        handover_load_n_[i] + laid * (params_.plate_weight_n + state.cell_load_n[i] - handover_load_n_[i]);
    filtered_load_n_[i] += alpha * (target - filtered_load_n_[i]);
    loads->data[i] = filtered_load_n_[i];
  }
  loads_pub_.publish(loads);
}

void Simulator::publishViews(const BodyState& state, const std::vector<double>& heights, const ros::Time& now) {
  const boost::shared_ptr<std_msgs::Float64> roll = boost::make_shared<std_msgs::Float64>();
  roll->data = state.roll_rad;
  roll_pub_.publish(roll);
  if (pressure_pub_.getNumSubscribers() > 0) publishPressure(state, now);
  if (last_markers_.isZero() || now < last_markers_ ||
      (now - last_markers_).toSec() >= 1.0 / params_.marker_rate_hz - 0.5 / params_.rate_hz) {
    if (markers_pub_.getNumSubscribers() > 0) publishMarkers(state, heights, now);
    publishTf(state, now);
    last_markers_ = now;
  }
}

void Simulator::recordStepTime(double took_s, int iterations) {
  step_time_sum_s_ += took_s;
  step_time_max_s_ = std::max(step_time_max_s_, took_s);
  if (++steps_ % static_cast<long>(std::max(1.0, 30.0 * params_.rate_hz)) == 0) {
    ROS_DEBUG("simulator: step %.3f ms mean, %.3f ms max over %ld steps (%d Newton iterations now)",
              1e3 * step_time_sum_s_ / steps_, 1e3 * step_time_max_s_, steps_, iterations);
  }
  if (took_s > 1.0 / params_.rate_hz)
    ROS_WARN_THROTTLE(10.0, "simulator: a step took %.1f ms, longer than the %.1f ms period (~rate_hz %g)",
                      1e3 * took_s, 1e3 / params_.rate_hz, params_.rate_hz);
}

void Simulator::step(const ros::Time& now) {
  std::lock_guard<std::mutex> step_lock(step_mutex_);
  const ros::WallTime wall_start = ros::WallTime::now();
  const CellSnapshot cells = snapshotCells();
  if (!coupled(now, cells)) return;

  BodyState state;
  try {
    state = body_->solve(cells.heights);
  } catch (const std::exception& e) {
    ROS_ERROR_THROTTLE(5.0, "simulator: %s", e.what());
    return;
  }
  if (!state.converged)
    ROS_WARN_THROTTLE(10.0, "simulator: the body's equilibrium did not converge (%d iterations)", state.iterations);
  publishLoads(state, cells.reported, now);
  publishViews(state, cells.heights, now);
  updateTissueLoad(cells.heights, now);
  recordStepTime((ros::WallTime::now() - wall_start).toSec(), state.iterations);
}

void Simulator::publishPressure(const BodyState& s, const ros::Time& now) {
  const boost::shared_ptr<InterfacePressure> out = boost::make_shared<InterfacePressure>();
  InterfacePressure& m = *out;
  m.header.stamp = now;
  m.header.frame_id = BedLayout::kBedLink;
  m.rows = static_cast<uint32_t>(layout_.rows());
  m.cols = static_cast<uint32_t>(layout_.cols());
  m.cell_load_n = s.cell_load_n;
  m.cell_pressure_pa = s.cell_pressure_pa;
  m.cell_peak_pressure_pa = s.cell_peak_pressure_pa;
  m.cell_pressure_mmhg.resize(s.cell_pressure_pa.size());
  m.cell_peak_pressure_mmhg.resize(s.cell_peak_pressure_pa.size());
  double peak = 0.0;
  uint32_t over = 0;
  for (std::size_t i = 0; i < s.cell_pressure_pa.size(); ++i) {
    m.cell_pressure_mmhg[i] = paToMmHg(s.cell_pressure_pa[i]);
    m.cell_peak_pressure_mmhg[i] = paToMmHg(s.cell_peak_pressure_pa[i]);
    peak = std::max(peak, m.cell_peak_pressure_mmhg[i]);
    if (m.cell_peak_pressure_mmhg[i] > InterfacePressure::CAPILLARY_CLOSING_MMHG) ++over;
  }
  m.peak_sacrum_mmhg = paToMmHg(s.peak_pressure_pa.sacrum);
  m.peak_heels_mmhg = paToMmHg(s.peak_pressure_pa.heels);
  m.peak_occiput_mmhg = paToMmHg(s.peak_pressure_pa.occiput);
  m.peak_cell_sacrum_mmhg = paToMmHg(s.peak_cell_pressure_pa.sacrum);
  m.peak_cell_heels_mmhg = paToMmHg(s.peak_cell_pressure_pa.heels);
  m.peak_cell_occiput_mmhg = paToMmHg(s.peak_cell_pressure_pa.occiput);
  m.peak_mmhg = peak;
  m.cells_over_threshold = over;
  m.body_roll_rad = s.roll_rad;
  m.total_load_n = s.total_load_n;
  pressure_pub_.publish(out);
}

void Simulator::updateTissueLoad(const std::vector<double>& heights, const ros::Time& now) {
  const bool first = last_tissue_.isZero() || now < last_tissue_;  // or time went back (a restarted /clock)
  const double dt = first ? 0.0 : (now - last_tissue_).toSec();
  if (!first && dt < 1.0 / params_.tissue_load_rate_hz - 0.5 / params_.rate_hz) return;
  const std::vector<ContactPoint> points = body_->contactMap(heights);
  tissue_->sample(measureRegions(points, tissue_->regions(), params_.patient.height_m), dt);
  last_tissue_ = now;
  double area_m2 = 0.0;
  for (const ContactPoint& p : points)
    if (p.pressure_pa > 0.0) area_m2 += p.area_m2;
  publishTissueLoad(now, area_m2);
}

void Simulator::publishTissueLoad(const ros::Time& now, double body_contact_area_m2) {
  const boost::shared_ptr<TissueLoad> out = boost::make_shared<TissueLoad>();
  TissueLoad& m = *out;
  m.header.stamp = now;
  m.header.frame_id = BedLayout::kBedLink;
  m.threshold_pa = tissue_->params().threshold_pa;
  m.observed_s = tissue_->observedS();
  m.body_contact_area_m2 = body_contact_area_m2;
  for (std::size_t r = 0; r < tissue_->regions().size(); ++r) {
    const RegionDose& d = tissue_->doses()[r];
    m.region.push_back(tissue_->regions()[r].name);
    m.peak_pressure_pa.push_back(d.now.peak_pressure_pa);
    m.peak_pressure_mmhg.push_back(paToMmHg(d.now.peak_pressure_pa));
    m.mean_pressure_pa.push_back(d.now.mean_pressure_pa);
    m.mean_pressure_mmhg.push_back(paToMmHg(d.now.mean_pressure_pa));
    m.contact_area_m2.push_back(d.now.contact_area_m2);
    m.force_n.push_back(d.now.force_n);
    m.margin_m.push_back(d.now.margin_m);
    m.min_margin_m.push_back(d.min_margin_m);
    m.max_peak_pressure_mmhg.push_back(paToMmHg(d.max_peak_pressure_pa));
    m.time_above_threshold_s.push_back(d.time_above_s);
    m.share_above_threshold.push_back(m.observed_s > 0.0 ? d.time_above_s / m.observed_s : 0.0);
    m.dose.push_back(d.dose);
  }
  tissue_pub_.publish(out);
}

void Simulator::publishMarkers(const BodyState& s, const std::vector<double>& heights, const ros::Time& now) {
  const boost::shared_ptr<visualization_msgs::MarkerArray> out = boost::make_shared<visualization_msgs::MarkerArray>();
  out->markers.push_back(plateMarker(layout_, s, heights, now));
  addSegmentMarkers(s, now, &out->markers);
  addNeckMarker(s, now, &out->markers);
  addPeakLabels(s, now, &out->markers);
  markers_pub_.publish(out);
}

void Simulator::publishTf(const BodyState& s, const ros::Time& now) {
  const SegmentPose& pelvis = s.segments[BodyModel::segmentIndex("pelvis")];
  const tf2::Transform body = segmentFrame(pelvis);
  const tf2::Transform body_inv = body.inverse();
  std::vector<geometry_msgs::TransformStamped> out;
  auto add = [&](const std::string& parent, const std::string& child, const tf2::Transform& t) {
    geometry_msgs::TransformStamped m;
    m.header.stamp = now;
    m.header.frame_id = parent;
    m.child_frame_id = child;
    m.transform.translation.x = t.getOrigin().x();
    m.transform.translation.y = t.getOrigin().y();
    m.transform.translation.z = t.getOrigin().z();
    m.transform.rotation = toMsg(t.getRotation());
    out.push_back(m);
  };
  add(BedLayout::kBedLink, sim_names::kBodyLink, body);
  for (const SegmentPose& seg : s.segments)
    add(sim_names::kBodyLink, "body_" + seg.name + "_link", body_inv * segmentFrame(seg));
  tf_->sendTransform(out);
}

}  // namespace nursing_bed
