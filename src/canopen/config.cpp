// The CANopen YAML reader. Strict: every key is known, every value has the
// right type and range; errors carry file:line. Kept in this one file so a
// shared strict reader can replace it later.
#include "manip/canopen/config.hpp"

#include "manip/common/yaml_reader.hpp"

#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>

namespace manip::canopen {

ObjectRef object_ref(PdoObject o) {
  switch (o) {
    case PdoObject::Controlword: return {0x6040, 0, 16};
    case PdoObject::TargetTorque: return {0x6071, 0, 16};
    case PdoObject::Statusword: return {0x6041, 0, 16};
    case PdoObject::PositionActual: return {0x6064, 0, 32};
    case PdoObject::VelocityActual: return {0x606C, 0, 32};
    case PdoObject::DigitalInputs: return {0x60FD, 0, 32};
  }
  return {0, 0, 0};
}

const char* to_string(PdoObject o) {
  switch (o) {
    case PdoObject::Controlword: return "controlword";
    case PdoObject::TargetTorque: return "target_torque";
    case PdoObject::Statusword: return "statusword";
    case PdoObject::PositionActual: return "position_actual";
    case PdoObject::VelocityActual: return "velocity_actual";
    case PdoObject::DigitalInputs: return "digital_inputs";
  }
  return "?";
}

int PdoMapping::bytes() const {
  int bits = 0;
  for (int i = 0; i < count; ++i) bits += object_ref(objects[i]).bits;
  return bits / 8;
}

bool PdoMapping::contains(PdoObject o) const {
  for (int i = 0; i < count; ++i)
    if (objects[i] == o) return true;
  return false;
}

AxisScaling AxisScaling::from(const DriveConfig& d) {
  AxisScaling a;
  a.counts_per_m = d.counts_per_m;
  a.velocity_units_per_count_s = d.velocity_units_per_count_s;
  a.rated_force_n = d.rated_force_n();
  a.max_torque_permille = d.max_torque_permille;
  a.sign = d.sign;
  a.workspace_axis = d.workspace_axis;
  return a;
}

int16_t AxisScaling::torque_permille(double force_n) const {
  double p = sign * force_n / rated_force_n * 1000.0;
  if (!std::isfinite(p)) p = 0;
  if (p > max_torque_permille) p = max_torque_permille;
  if (p < -max_torque_permille) p = -max_torque_permille;
  return static_cast<int16_t>(std::lround(p));
}

namespace {

struct Reader {
  std::string source;
  std::vector<std::string>& errors;

  void fail(const YAML::Node& n, const std::string& key, const std::string& why) {
    std::ostringstream s;
    s << source << ":" << (n.Mark().line >= 0 ? n.Mark().line + 1 : 0) << ": " << key << ": " << why;
    errors.push_back(s.str());
  }

  bool scalar(const YAML::Node& n, const std::string& key) {
    if (!n.IsScalar()) {
      fail(n, key, "expected a scalar value");
      return false;
    }
    return true;
  }

  template <class T>
  void integer(const YAML::Node& n, const std::string& key, T& out, long long lo, long long hi) {
    if (!scalar(n, key)) return;
    const std::string s = n.Scalar();
    errno = 0;
    char* end = nullptr;
    const long long v = std::strtoll(s.c_str(), &end, 0);  // accepts 0x.. hex (object values)
    if (s.empty() || *end != '\0' || errno != 0) {
      fail(n, key, "expected an integer, got '" + s + "'");
      return;
    }
    if (v < lo || v > hi) {
      fail(n, key, "value " + s + " out of range [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
      return;
    }
    out = static_cast<T>(v);
  }

  void real(const YAML::Node& n, const std::string& key, double& out, double lo, double hi) {
    if (!scalar(n, key)) return;
    const std::string s = n.Scalar();
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    if (s.empty() || *end != '\0' || !std::isfinite(v)) {
      fail(n, key, "expected a number, got '" + s + "'");
      return;
    }
    if (v < lo || v > hi) {
      std::ostringstream r;
      r << "value " << s << " out of range [" << lo << ", " << hi << "]";
      fail(n, key, r.str());
      return;
    }
    out = v;
  }

  void text(const YAML::Node& n, const std::string& key, std::string& out) {
    if (!scalar(n, key)) return;
    if (n.Scalar().empty()) {
      fail(n, key, "must not be empty");
      return;
    }
    out = n.Scalar();
  }

  void boolean(const YAML::Node& n, const std::string& key, bool& out) {
    if (!scalar(n, key)) return;
    const std::string& s = n.Scalar();
    if (s == "true") out = true;
    else if (s == "false") out = false;
    else fail(n, key, "expected true or false, got '" + s + "'");
  }

  void mapping(const YAML::Node& n, const std::string& key, PdoMapping& out, bool rx) {
    if (!n.IsSequence()) {
      fail(n, key, "expected a list of object names");
      return;
    }
    PdoMapping m;
    for (const auto& e : n) {
      if (!scalar(e, key)) return;
      const std::string s = e.Scalar();
      PdoObject o;
      if (rx && s == "controlword") o = PdoObject::Controlword;
      else if (rx && s == "target_torque") o = PdoObject::TargetTorque;
      else if (!rx && s == "statusword") o = PdoObject::Statusword;
      else if (!rx && s == "position_actual") o = PdoObject::PositionActual;
      else if (!rx && s == "velocity_actual") o = PdoObject::VelocityActual;
      else if (!rx && s == "digital_inputs") o = PdoObject::DigitalInputs;
      else {
        fail(e, key, "unknown " + std::string(rx ? "RPDO" : "TPDO") + " object '" + s + "' (allowed: " +
                         (rx ? "controlword, target_torque" : "statusword, position_actual, velocity_actual, digital_inputs") + ")");
        return;
      }
      if (m.contains(o)) {
        fail(e, key, "object '" + s + "' mapped twice");
        return;
      }
      m.add(o);
    }
    if (m.bytes() > 8) {
      fail(n, key, "mapping needs " + std::to_string(m.bytes()) + " bytes, a CAN PDO carries at most 8");
      return;
    }
    out = m;
  }
};

void read_master(Reader& r, const YAML::Node& n, MasterConfig& m) {
  if (!n.IsMap()) return r.fail(n, "master", "expected a mapping");
  for (const auto& kv : n) {
    const std::string k = manip::yaml::scalar_text(kv.first);
    const YAML::Node& v = kv.second;
    const std::string key = "master." + k;
    if (k == "node_id") r.integer(v, key, m.node_id, 1, 127);
    else if (k == "sync_period_us") r.integer(v, key, m.sync_period_us, 250, 100000);
    else if (k == "heartbeat_ms") r.integer(v, key, m.heartbeat_ms, 1, 65535);
    else if (k == "boot_timeout_ms") r.integer(v, key, m.boot_timeout_ms, 1, 600000);
    else if (k == "sdo_timeout_ms") r.integer(v, key, m.sdo_timeout_ms, 1, 60000);
    else if (k == "enable_timeout_ms") r.integer(v, key, m.enable_timeout_ms, 1, 60000);
    else if (k == "fault_reset_timeout_ms") r.integer(v, key, m.fault_reset_timeout_ms, 1, 60000);
    else if (k == "max_bus_load") r.real(v, key, m.max_bus_load, 0.01, 1.0);
    else if (k == "tpdo_miss_limit") r.integer(v, key, m.tpdo_miss_limit, 1, 1000);
    else if (k == "emcy_headroom_hz") r.real(v, key, m.emcy_headroom_hz, 0.0, 10000.0);
    else r.fail(kv.first, key, "unknown key");
  }
}

void read_drive(Reader& r, const YAML::Node& n, const std::string& prefix, DriveConfig& d, bool defaults) {
  if (!n.IsMap()) return r.fail(n, prefix, "expected a mapping");
  for (const auto& kv : n) {
    const std::string k = manip::yaml::scalar_text(kv.first);
    const YAML::Node& v = kv.second;
    const std::string key = prefix + "." + k;
    if (k == "bus") r.text(v, key, d.bus);
    else if (k == "node_id" && !defaults) r.integer(v, key, d.node_id, 1, 127);
    else if (k == "workspace_axis" && !defaults) r.integer(v, key, d.workspace_axis, 0, 1);
    else if (k == "sign") {
      int s = 0;
      r.integer(v, key, s, -1, 1);
      if (s == 0 && v.IsScalar() && v.Scalar() == "0") r.fail(v, key, "must be +1 or -1");
      else if (s != 0) d.sign = s;
    } else if (k == "counts_per_m") r.real(v, key, d.counts_per_m, 1e-3, 1e12);
    else if (k == "velocity_units_per_count_s") r.real(v, key, d.velocity_units_per_count_s, 1e-6, 1e6);
    else if (k == "rated_current_a") r.real(v, key, d.rated_current_a, 1e-3, 1000.0);
    else if (k == "force_constant_n_per_a") r.real(v, key, d.force_constant_n_per_a, 1e-3, 10000.0);
    else if (k == "max_torque_permille") r.integer(v, key, d.max_torque_permille, 1, 32767);
    else if (k == "heartbeat_producer_ms") r.integer(v, key, d.heartbeat_producer_ms, 1, 65535);
    else if (k == "heartbeat_timeout_ms") r.integer(v, key, d.heartbeat_timeout_ms, 1, 65535);
    else if (k == "master_heartbeat_timeout_ms") r.integer(v, key, d.master_heartbeat_timeout_ms, 1, 65535);
    else if (k == "abort_connection_option") r.integer(v, key, d.abort_connection_option, -32768, 32767);
    else if (k == "vendor_id") r.integer(v, key, d.vendor_id, 0, 0xFFFFFFFFLL);
    else if (k == "product_code") r.integer(v, key, d.product_code, 0, 0xFFFFFFFFLL);
    else if (k == "event_status_register") r.boolean(v, key, d.event_status_register);
    else if (k == "rpdo") r.mapping(v, key, d.rpdo, true);
    else if (k == "tpdo") r.mapping(v, key, d.tpdo, false);
    else if (k == "tpdo2") r.mapping(v, key, d.tpdo2, false);
    else if (k == "drive_profile") {
      std::string p;
      r.text(v, key, p);
      if (!p.empty() && p != "cia402_cst") r.fail(v, key, "only 'cia402_cst' (cyclic synchronous torque, mode 10) is supported");
    } else r.fail(kv.first, key, defaults ? "unknown key (or not allowed in defaults)" : "unknown key");
  }
}

void read_backend(Reader& r, const YAML::Node& n, BackendOptions& b) {
  if (!n.IsMap()) return r.fail(n, "backend", "expected a mapping");
  for (const auto& kv : n) {
    const std::string k = manip::yaml::scalar_text(kv.first);
    const YAML::Node& v = kv.second;
    const std::string key = "backend." + k;
    if (k == "virtual") r.boolean(v, key, b.virtual_bus);
    else if (k == "estop_statusword_bit") {
      r.integer(v, key, b.estop_statusword_bit, -1, 15);
      const int bit = b.estop_statusword_bit;
      if (bit >= 0 && bit != 8 && bit != 14 && bit != 15)
        r.fail(v, key, "must be -1 (not wired) or a manufacturer-specific statusword bit (8, 14, 15)");
    } else if (k == "estop_active_high") r.boolean(v, key, b.estop_active_high);
    else if (k == "estop_input_bit") r.integer(v, key, b.estop_input_bit, -1, 31);
    else if (k == "estop_input_open_high") r.boolean(v, key, b.estop_input_open_high);
    else if (k == "estop_on_voltage_loss") r.boolean(v, key, b.estop_on_voltage_loss);
    else if (k == "force_sensor") {
      r.text(v, key, b.force_sensor);
      if (b.force_sensor != "sim" && b.force_sensor != "netft" && b.force_sensor != "jr3" && b.force_sensor != "none")
        r.fail(v, key, "expected sim, netft, jr3 or none");
    } else if (k == "tare") r.boolean(v, key, b.tare);
    else if (k == "tare_samples") r.integer(v, key, b.tare_samples, 1, 100000);
    else if (k == "force_full_scale_n") r.real(v, key, b.force_full_scale_n, 1.0, 1e5);
    else if (k == "force_stale_cycles") r.integer(v, key, b.force_stale_cycles, 1, 100000);
    else if (k == "sensor_rotation_deg") r.real(v, key, b.sensor_rotation_deg, -360.0, 360.0);
    else if (k == "netft_address") r.text(v, key, b.netft_address);
    else if (k == "netft_port") r.integer(v, key, b.netft_port, 1, 65535);
    else if (k == "netft_counts_per_force") r.real(v, key, b.netft_counts_per_force, 1e-6, 1e12);
    else if (k == "jr3_device") r.text(v, key, b.jr3_device);
    else if (k == "jr3_filter") r.integer(v, key, b.jr3_filter, 0, 6);
    else if (k == "record_raw_frames") r.boolean(v, key, b.record_raw_frames);
    else if (k == "raw_queue_frames") r.integer(v, key, b.raw_queue_frames, 1024, 4u << 20);
    else r.fail(kv.first, key, "unknown key");
  }
}

}  // namespace

namespace {
bool parse_config_checked(const std::string& text, const std::string& source, CanConfig& out,
                          std::vector<std::string>& errors) {
  const std::size_t errors_before = errors.size();
  Reader r{source, errors};
  YAML::Node root;
  try {
    // The one strict YAML parse of manip: syntax errors and duplicate keys
    // (yaml-cpp would silently keep the first of two) name the file and line.
    root = manip::yaml::parse(text, source);
  } catch (const manip::ConfigError& e) {
    errors.push_back(e.what());
    return false;
  }
  if (!root.IsMap()) {
    errors.push_back(source + ":1: <root>: expected a mapping with master, buses, defaults, nodes");
    return false;
  }
  CanConfig cfg;
  cfg.source = source;
  DriveConfig defaults;
  defaults.rpdo.add(PdoObject::Controlword);
  defaults.rpdo.add(PdoObject::TargetTorque);
  defaults.tpdo.add(PdoObject::Statusword);
  defaults.tpdo.add(PdoObject::PositionActual);
  YAML::Node nodes, buses;
  for (const auto& kv : root) {
    const std::string k = manip::yaml::scalar_text(kv.first);
    if (k == "master") read_master(r, kv.second, cfg.master);
    else if (k == "defaults") read_drive(r, kv.second, "defaults", defaults, true);
    else if (k == "buses") buses = kv.second;
    else if (k == "nodes") nodes = kv.second;
    else if (k == "backend") read_backend(r, kv.second, cfg.backend);
    else r.fail(kv.first, k, "unknown key (allowed: master, buses, defaults, nodes, backend)");
  }
  if (!buses || !buses.IsMap() || buses.size() == 0) {
    r.fail(buses ? buses : root, "buses", "required: a mapping of bus name -> {interface, bitrate}");
  } else {
    for (const auto& kv : buses) {
      BusConfig b;
      b.name = manip::yaml::scalar_text(kv.first);
      const std::string prefix = "buses." + b.name;
      if (!kv.second.IsMap()) {
        r.fail(kv.second, prefix, "expected a mapping");
        continue;
      }
      for (const auto& f : kv.second) {
        const std::string k = manip::yaml::scalar_text(f.first);
        if (k == "interface") r.text(f.second, prefix + ".interface", b.interface);
        else if (k == "bitrate") r.integer(f.second, prefix + ".bitrate", b.bitrate, 10000, 1000000);
        else r.fail(f.first, prefix + "." + k, "unknown key (allowed: interface, bitrate)");
      }
      if (b.interface.empty()) r.fail(kv.second, prefix + ".interface", "required");
      for (const auto& o : cfg.buses)
        if (o.interface == b.interface && !b.interface.empty())
          r.fail(kv.second, prefix + ".interface", "interface '" + b.interface + "' used by two buses");
      cfg.buses.push_back(b);
    }
  }
  if (!nodes || !nodes.IsMap() || nodes.size() == 0) {
    r.fail(nodes ? nodes : root, "nodes", "required: a mapping of drive name -> settings");
  } else {
    for (const auto& kv : nodes) {
      DriveConfig d = defaults;
      d.name = manip::yaml::scalar_text(kv.first);
      const std::string prefix = "nodes." + d.name;
      read_drive(r, kv.second, prefix, d, false);
      const YAML::Node& at = kv.second;
      if (d.node_id == 0) r.fail(at, prefix + ".node_id", "required (1..127)");
      if (d.node_id == cfg.master.node_id) r.fail(at, prefix + ".node_id", "equals master.node_id");
      if (d.counts_per_m <= 0) r.fail(at, prefix + ".counts_per_m", "required (> 0)");
      if (d.rated_current_a <= 0) r.fail(at, prefix + ".rated_current_a", "required (> 0)");
      if (d.force_constant_n_per_a <= 0) r.fail(at, prefix + ".force_constant_n_per_a", "required (> 0)");
      bool bus_found = false;
      for (const auto& b : cfg.buses) bus_found |= b.name == d.bus;
      if (!bus_found) r.fail(at, prefix + ".bus", d.bus.empty() ? "required" : "unknown bus '" + d.bus + "'");
      if (!d.rpdo.contains(PdoObject::Controlword) || !d.rpdo.contains(PdoObject::TargetTorque))
        r.fail(at, prefix + ".rpdo", "must map controlword and target_torque (CST, mode 10)");
      if (!d.tpdo.contains(PdoObject::Statusword) || !d.tpdo.contains(PdoObject::PositionActual))
        r.fail(at, prefix + ".tpdo", "must map statusword and position_actual");
      for (int i = 0; i < d.tpdo2.count; ++i)
        if (d.tpdo.contains(d.tpdo2.objects[i])) r.fail(at, prefix + ".tpdo2", "object already in tpdo");
      if (cfg.backend.estop_input_bit >= 0 && !d.tpdo.contains(PdoObject::DigitalInputs) &&
          !d.tpdo2.contains(PdoObject::DigitalInputs))
        r.fail(at, prefix + ".tpdo2",
               "backend.estop_input_bit needs digital_inputs (0x60FD) mapped in tpdo or tpdo2 of every drive");
      if (d.heartbeat_timeout_ms <= d.heartbeat_producer_ms)
        r.fail(at, prefix + ".heartbeat_timeout_ms", "must exceed heartbeat_producer_ms");
      if (d.master_heartbeat_timeout_ms <= cfg.master.heartbeat_ms)
        r.fail(at, prefix + ".master_heartbeat_timeout_ms", "must exceed master.heartbeat_ms");
      for (const auto& o : cfg.drives) {
        if (o.bus == d.bus && o.node_id == d.node_id)
          r.fail(at, prefix + ".node_id", "node id " + std::to_string(d.node_id) + " used twice on bus " + d.bus);
        if (o.workspace_axis == d.workspace_axis)
          r.fail(at, prefix + ".workspace_axis", "axis " + std::to_string(d.workspace_axis) + " already driven by " + o.name);
      }
      cfg.drives.push_back(d);
    }
  }
  if (errors.size() != errors_before) return false;
  out = std::move(cfg);
  return true;
}
}  // namespace

bool parse_config(const std::string& text, const std::string& source, CanConfig& out,
                  std::vector<std::string>& errors) {
  // A second line of defence (fuzz_can_config found a key that was a mapping):
  // whatever yaml-cpp throws on hostile input becomes a refusal naming the file.
  try {
    return parse_config_checked(text, source, out, errors);
  } catch (const YAML::Exception& e) {
    errors.push_back(source + ":" + std::to_string(e.mark.line + 1) + ": <yaml>: " + e.msg);
    return false;
  }
}

bool load_config(const std::string& path, CanConfig& out, std::vector<std::string>& errors) {
  std::ifstream f(path);
  if (!f) {
    errors.push_back(path + ":0: <file>: cannot open");
    return false;
  }
  std::stringstream ss;
  ss << f.rdbuf();
  return parse_config(ss.str(), path, out, errors);
}

}  // namespace manip::canopen
