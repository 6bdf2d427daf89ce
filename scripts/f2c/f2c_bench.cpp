// Plans one field with Fields2Cover 2.1.0 (built by scripts/f2c/build.sh)
// for terraplan's coverage benchmark (scripts/bench_coverage.py) and prints
// the plan as JSON on stdout: the lanes in flown order and direction, the
// path from the first lane's start to the last lane's end, the cell count,
// the swath angle and the planning time.
//
//   f2c_bench --field FIELD.wkt --width METRES --mode single|decomp
//             [--time-limit SECONDS]
//
// FIELD.wkt: one POLYGON in metres (a projected CRS; its holes are the
// obstacles). Modes:
//   single  BruteForce swaths (NSwath objective, 1 degree steps) over the
//           whole field, Boustrophedon order (the best of its four start
//           variants by path length), straight links between lanes. No
//           route solver: this is Fields2Cover's single-cell pipeline.
//   decomp  Boustrophedon decomposition split along the field's best swath
//           angle, BruteForce swaths (NSwath) per cell, and
//           RoutePlannerBase::genRoute to order the swaths of all cells,
//           linked along the cell borders. genRoute's OR-tools solver is
//           replaced by scripts/f2c/no-ortools.patch.
// Exit status 2 for bad arguments or an unreadable field, 1 if planning
// fails.

#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "fields2cover.h"

namespace {

struct Args {
  std::string field;
  double width {0.0};
  std::string mode {"single"};
  long time_limit_s {1};
};

[[noreturn]] void usage(const std::string& why) {
  std::cerr << "f2c_bench: " << why << "\nusage: f2c_bench --field FIELD.wkt"
    " --width METRES --mode single|decomp [--time-limit SECONDS]\n";
  std::exit(2);
}

Args parseArgs(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    std::string k = argv[i];
    if (i + 1 >= argc) {
      usage("missing value after " + k);
    }
    std::string v = argv[++i];
    try {
      if (k == "--field") {
        a.field = v;
      } else if (k == "--width") {
        a.width = std::stod(v);
      } else if (k == "--mode") {
        a.mode = v;
      } else if (k == "--time-limit") {
        a.time_limit_s = std::stol(v);
      } else {
        usage("unknown option " + k);
      }
    } catch (const std::logic_error&) {
      usage("not a number after " + k + ": " + v);
    }
  }
  if (a.field.empty()) {
    usage("--field is required");
  }
  if (!(a.width > 0.0)) {
    usage("--width must be a positive number of metres");
  }
  if (a.mode != "single" && a.mode != "decomp") {
    usage("--mode must be single or decomp, not " + a.mode);
  }
  if (a.time_limit_s < 1) {
    usage("--time-limit must be at least 1 s");
  }
  return a;
}

F2CCell readField(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    std::cerr << "f2c_bench: cannot read " << path << "\n";
    std::exit(2);
  }
  std::stringstream ss;
  ss << in.rdbuf();
  F2CCell cell;
  cell.importFromWkt(ss.str());
  if (cell.isEmpty() || !(cell.area() > 0.0)) {
    std::cerr << "f2c_bench: " << path << " holds no POLYGON with an area\n";
    std::exit(2);
  }
  return cell;
}

nlohmann::json pointJson(const F2CPoint& p) {
  return {p.getX(), p.getY()};
}

// The single-cell pipeline: one swath set, four Boustrophedon variants.
F2CRoute planSingle(const F2CCell& field, double width, double* angle) {
  f2c::sg::BruteForce bf;
  f2c::obj::NSwath n_swath;
  *angle = bf.computeBestAngle(n_swath, width, field);
  F2CSwaths swaths = bf.generateSwaths(*angle, width, field);
  f2c::rp::BoustrophedonOrder order;
  F2CRoute best;
  double best_len = INFINITY;
  for (uint32_t variant = 0; variant < 4; ++variant) {
    F2CRoute route;
    for (auto&& s : order.genSortedSwaths(swaths, variant)) {
      route.addSwath(s);
    }
    double len = route.length();
    if (len < best_len) {
      best_len = len;
      best = route;
    }
  }
  return best;
}

F2CRoute planDecomp(const F2CCell& field, double width, long time_limit_s,
    double* angle, size_t* n_cells) {
  f2c::sg::BruteForce bf;
  f2c::obj::NSwath n_swath;
  *angle = bf.computeBestAngle(n_swath, width, field);
  f2c::decomp::BoustrophedonDecomp decomp;
  decomp.setSplitAngle(*angle);
  F2CCells cells = decomp.decompose(F2CCells(field));
  *n_cells = cells.size();
  F2CSwathsByCells swaths = bf.generateBestSwaths(n_swath, width, cells);
  f2c::rp::RoutePlannerBase planner;
  return planner.genRoute(cells, swaths, false, 1e-4, true, time_limit_s,
      true);
}

}  // namespace

int main(int argc, char** argv) {
  Args args = parseArgs(argc, argv);
  F2CCell field = readField(args.field);
  auto t0 = std::chrono::steady_clock::now();
  double angle = 0.0;
  size_t n_cells = 1;
  F2CRoute route;
  try {
    route = args.mode == "single" ?
      planSingle(field, args.width, &angle) :
      planDecomp(field, args.width, args.time_limit_s, &angle, &n_cells);
  } catch (const std::exception& e) {
    std::cerr << "f2c_bench: planning failed: " << e.what() << "\n";
    return 1;
  }
  double plan_s = std::chrono::duration<double>(
      std::chrono::steady_clock::now() - t0).count();

  nlohmann::json lanes = nlohmann::json::array();
  for (auto&& group : route.getVectorSwaths()) {
    for (auto&& s : group) {
      nlohmann::json lane = nlohmann::json::array();
      for (auto&& p : s.getPath()) {
        lane.push_back(pointJson(p));
      }
      lanes.push_back(lane);
    }
  }
  nlohmann::json path = nlohmann::json::array();
  for (auto&& p : route.asLineString()) {
    path.push_back(pointJson(p));
  }
  nlohmann::json out = {
    {"mode", args.mode},
    {"cells", n_cells},
    {"angle_deg", angle * 180.0 / M_PI},
    {"plan_s", plan_s},
    {"lanes", lanes},
    {"path", path},
  };
  std::cout << out.dump() << "\n";
  return 0;
}
