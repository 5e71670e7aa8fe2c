#include "options.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <set>
#include <type_traits>

#include <nlohmann/json.hpp>

namespace ldimesh {
namespace {

Status bad(const std::string& key, const std::string& why) {
  return Status::invalid_options("options: '" + key + "' " + why);
}

// Every key of `obj` (named prefix + key) is one of `known`.
Status check_keys(const nlohmann::json& obj, const std::string& prefix,
                  std::initializer_list<const char*> known) {
  for (auto it = obj.begin(); it != obj.end(); ++it) {
    bool found = false;
    for (const char* k : known)
      found = found || it.key() == k;
    if (!found) return bad(prefix + it.key(), "is not a known option (see docs/adaptor.md)");
  }
  return Status::ok();
}

// Integer option obj[key] (named prefix + key), if present: a JSON number with an integral
// value in [lo, hi], checked before any conversion (a double out of an integer type's range
// would be undefined behaviour).
template <class Integer>
Status integer(const nlohmann::json& obj, const char* key, const std::string& prefix, double lo,
               double hi, Integer& out) {
  if (!obj.contains(key)) return Status::ok();
  const nlohmann::json& v = obj[key];
  const double x = v.is_number() ? v.get<double>() : NAN;
  if (!(x >= lo && x <= hi && std::floor(x) == x))
    return bad(prefix + key, "must be an integer in " + std::to_string(std::int64_t(lo)) + ".." +
                                 std::to_string(std::int64_t(hi)));
  out = static_cast<Integer>(x);
  return Status::ok();
}

// Counts: up to 2^53, where doubles still hold every integer.
constexpr double kMaxCount = 9007199254740992.0;

// "colour_by" (`v`), after "isovalues": one field's name for every isosurface, or an array of
// a name or null per isovalue (null: that isosurface is not coloured), or null (none is).
Status parse_colour_by(const nlohmann::json& v, AdaptorOptions& o) {
  std::vector<std::string> names;
  if (v.is_null()) {  // nothing coloured
    names.assign(o.isovalues.size(), std::string());
  } else if (v.is_string()) {
    names.assign(o.isovalues.size(), v.get<std::string>());
    if (names.front().empty())
      return bad("colour_by", "must name a field (add_field), or be left out");
  } else if (v.is_array()) {
    if (v.size() != o.isovalues.size())
      return bad("colour_by", "must have one entry per isovalue (" +
                                  std::to_string(o.isovalues.size()) +
                                  "), a field's name or null; it has " + std::to_string(v.size()));
    for (const auto& x : v) {
      if (!x.is_null() && !(x.is_string() && !x.get<std::string>().empty()))
        return bad("colour_by", "entries must be a field's name (add_field) or null");
      names.push_back(x.is_null() ? std::string() : x.get<std::string>());
    }
  } else {
    return bad(
        "colour_by",
        "must be a field's name (a string), an array of a name or null per isovalue, or null");
  }
  o.colour_fields.clear();
  o.surface_field.assign(names.size(), -1);
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (names[i].empty()) continue;
    const auto at = std::find(o.colour_fields.begin(), o.colour_fields.end(), names[i]);
    o.surface_field[i] = int(at - o.colour_fields.begin());
    if (at == o.colour_fields.end()) o.colour_fields.push_back(names[i]);
  }
  if (o.colour_fields.empty()) o.surface_field.clear();
  return Status::ok();
}

// What is cast: "isovalues", "colour_by", "views", "resolution", "r".
Status parse_surfaces(const nlohmann::json& j, AdaptorOptions& o) {
  if (j.contains("isovalues")) {
    const auto& v = j["isovalues"];
    if (!v.is_array() || v.empty()) return bad("isovalues", "must be a non-empty array of numbers");
    o.isovalues.clear();
    for (const auto& x : v) {
      if (!x.is_number()) return bad("isovalues", "must be a non-empty array of numbers");
      o.isovalues.push_back(x.get<double>());
    }
    if (o.isovalues.size() > 8) return bad("isovalues", "may hold at most 8 values");
  }
  if (j.contains("colour_by")) {
    if (Status s = parse_colour_by(j["colour_by"], o); !s) return s;
  }
  if (j.contains("views")) {
    o.views = j["views"].get<std::string>();
    if (o.views.empty()) return bad("views", "must name at least one axis");
    std::set<char> seen;
    for (char c : o.views)
      if ((c != 'x' && c != 'y' && c != 'z') || !seen.insert(c).second)
        return bad("views", "must be a subset of \"xyz\"");
  }
  if (Status s = integer(j, "resolution", "", 2, 8192, o.resolution); !s) return s;
  if (j.contains("r")) {
    o.r = j["r"].get<double>();
    if (!(o.r >= 0.0 && o.r <= 1.0)) return bad("r", "must lie in [0, 1]");
  }
  return Status::ok();
}

// How the views are meshed beyond §3: "refinement" (§4), "merging" (§5).
Status parse_meshing(const nlohmann::json& j, AdaptorOptions& o) {
  if (j.contains("refinement")) {
    // true: two levels (a quarter of the pixel spacing where the surface curves); a number:
    // that many levels; false or 0: off.
    const nlohmann::json& v = j["refinement"];
    if (v.is_boolean())
      o.refinement_levels = v.get<bool>() ? 2 : 0;
    else if (Status s = integer(j, "refinement", "", 0, 6, o.refinement_levels); !s)
      return bad("refinement", "must be true, false or a number of levels in 0..6");
  }
  if (j.contains("merging")) {
    const nlohmann::json& v = j["merging"];
    if (v.is_boolean())
      o.merging = v.get<bool>() ? AdaptorOptions::Merging::on : AdaptorOptions::Merging::off;
    else if (v.is_string() && v.get<std::string>() == "auto")
      o.merging = AdaptorOptions::Merging::automatic;
    else
      return bad("merging", "must be true, false or \"auto\"");
  }
  return Status::ok();
}

// When steps run: "cadence", "busy".
Status parse_schedule(const nlohmann::json& j, AdaptorOptions& o) {
  if (j.contains("cadence")) {
    const auto& c = j["cadence"];
    if (Status s = check_keys(c, "cadence.", {"every_steps", "every_seconds"}); !s) return s;
    if (Status s = integer(c, "every_steps", "cadence.", 1, kMaxCount, o.every_steps); !s) return s;
    if (c.contains("every_seconds")) {
      o.every_seconds = c["every_seconds"].get<double>();
      if (!(o.every_seconds >= 0.0)) return bad("cadence.every_seconds", "must be ≥ 0");
    }
  }
  if (j.contains("busy")) {
    const std::string b = j["busy"].get<std::string>();
    if (b != "skip" && b != "coalesce") return bad("busy", "must be \"skip\" or \"coalesce\"");
    o.coalesce = b == "coalesce";
  }
  return Status::ok();
}

// Where steps go and how: "server", "output_dir", "keep", "memory_mb", "encoding", "glb", "log".
Status parse_delivery(const nlohmann::json& j, AdaptorOptions& o) {
  if (j.contains("server")) {
    const auto& s = j["server"];
    if (Status st = check_keys(s, "server.", {"enabled", "bind", "allow_remote", "port", "token"});
        !st)
      return st;
    if (s.contains("enabled")) o.server = s["enabled"].get<bool>();
    if (s.contains("bind")) o.bind = s["bind"].get<std::string>();
    if (s.contains("allow_remote")) o.allow_remote = s["allow_remote"].get<bool>();
    if (Status st = integer(s, "port", "server.", 0, 65535, o.port); !st) return st;
    if (s.contains("token")) o.token = s["token"].get<std::string>();
  }
  if (j.contains("output_dir")) o.output_dir = j["output_dir"].get<std::string>();
  if (Status s = integer(j, "keep", "", 1, kMaxCount, o.keep); !s) return s;
  if (Status s = integer(j, "memory_mb", "", 1, kMaxCount, o.memory_mb); !s) return s;
  if (j.contains("encoding")) {
    const auto& e = j["encoding"];
    if (Status s =
            check_keys(e, "encoding.", {"lossless", "depth_bits", "normal_bits", "scalar_bits"});
        !s)
      return s;
    if (e.contains("lossless")) o.encoding.lossless = e["lossless"].get<bool>();
    if (Status s = integer(e, "depth_bits", "encoding.", 1, 24, o.encoding.depth_bits); !s)
      return s;
    if (Status s = integer(e, "scalar_bits", "encoding.", 2, 24, o.encoding.scalar_bits); !s)
      return s;
    if (Status s = integer(e, "normal_bits", "encoding.", 2, 16, o.encoding.normal_bits); !s)
      return s;
  }
  if (j.contains("glb")) {
    const auto& g = j["glb"];
    if (Status s = check_keys(g, "glb.", {"compression_level", "normal_bits", "scalar_bits"}); !s)
      return s;
    if (Status s = integer(g, "compression_level", "glb.", 0, 10, o.glb.compression_level); !s)
      return s;
    if (Status s = integer(g, "normal_bits", "glb.", 2, 16, o.glb.normal_bits); !s) return s;
    if (Status s = integer(g, "scalar_bits", "glb.", 1, 16, o.glb.scalar_bits); !s) return s;
  }
  if (j.contains("log")) o.log = j["log"].get<bool>();
  return Status::ok();
}

// "testing": a slow root, injected faults.
Status parse_testing(const nlohmann::json& t, AdaptorOptions& o) {
  if (Status s = check_keys(t, "testing.", {"slow_root_seconds", "fault"}); !s) return s;
  if (t.contains("slow_root_seconds")) o.slow_root_seconds = t["slow_root_seconds"].get<double>();
  if (t.contains("fault")) {
    const auto& f = t["fault"];
    if (Status s = check_keys(f, "testing.fault.", {"kind", "step", "rank"}); !s) return s;
    o.fault = f.at("kind").get<std::string>();
    if (o.fault != "out_of_memory" && o.fault != "exception" && o.fault != "corrupt_message")
      return bad("testing.fault.kind",
                 "must be \"out_of_memory\", \"exception\" or \"corrupt_message\"");
    if (Status s = integer(f, "step", "testing.fault.", 0, kMaxCount, o.fault_step); !s) return s;
    if (Status s = integer(f, "rank", "testing.fault.", 0, INT32_MAX, o.fault_rank); !s) return s;
    // The root sends no message in the reduction: only another rank's can be damaged.
    if (o.fault == "corrupt_message" && o.fault_rank < 1)
      return bad("testing.fault.rank", "must be a rank other than the root (≥ 1)");
  }
  return Status::ok();
}

// Reads `j` into `o`, naming the first unknown key or bad value.
Status parse_object(const nlohmann::json& j, AdaptorOptions& o) {
  if (!j.is_object()) return Status::invalid_options("options: the document must be a JSON object");
  LDIMESH_RETURN_IF_ERROR(
      check_keys(j, "",
                 {"isovalues", "colour_by", "views", "resolution", "r", "cadence", "busy",
                  "refinement", "merging", "server", "output_dir", "keep", "memory_mb", "encoding",
                  "glb", "log", "background", "testing"}));
  try {
    // In the order the options are documented (docs/adaptor.md): the first bad one is named.
    LDIMESH_RETURN_IF_ERROR(parse_surfaces(j, o));
    LDIMESH_RETURN_IF_ERROR(parse_schedule(j, o));
    LDIMESH_RETURN_IF_ERROR(parse_meshing(j, o));
    LDIMESH_RETURN_IF_ERROR(parse_delivery(j, o));
    if (j.contains("background")) o.background = j["background"].get<bool>();
    if (j.contains("testing")) LDIMESH_RETURN_IF_ERROR(parse_testing(j["testing"], o));
  } catch (const nlohmann::json::exception& e) {
    return Status::invalid_options(std::string("options: a value has the wrong type: ") + e.what());
  }
  return Status::ok();
}

}  // namespace

Status parse_adaptor_options(std::string_view json, AdaptorOptions& out) {
  try {
    const nlohmann::json j = nlohmann::json::parse(json, nullptr, false);
    if (j.is_discarded()) return Status::invalid_options("options: not a valid JSON document");
    return parse_object(j, out);
  } catch (const std::exception& e) {  // allocation failure included
    return Status::invalid_options(std::string("options: cannot be read: ") + e.what());
  }
}

}  // namespace ldimesh
