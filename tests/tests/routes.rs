//! The routes resource end to end over HTTP, against the real binary and
//! the real DTM `opengeos_data__elevation_dtm.tif` (283 × 259 cells of
//! 2 m, NAD83 / UTM 18N): a costmap is built, its GeoTIFF read back with
//! GDAL to pick the start and goal (the traversable regions are found in
//! the test, 8-connected without corner cutting as the planner moves), a
//! route planned and checked against the costmap and the DEM, its files
//! (GeoJSON, CSV, a Rover mission loaded by pymavlink), replans around a
//! blocked area (D* Lite repairing the held search, and rebuilding it),
//! 422s naming pointers, 409 on unfinished costmaps, 503 on a search over
//! the time limit, listing and delete. Runs on SQLite, and on PostgreSQL
//! when the test command sets `TERRAPLAN_TEST_DATABASE_URL`.

use std::collections::VecDeque;
use std::path::Path;

use geo::Intersects;
use geo_types::{Coord, Line, LineString, Polygon};
use serde_json::{Value, json};
use terraplan_e2e::{
    Reply, Server, assert_invalid_at, assert_problem, band_values, class_page, close, delete, dtm,
    egm96_undulations, gdalinfo, get, pixel_values, post, post_json, run_tool,
    slow_costmap_options, text, upload_dem, validator, wait_costmap_finished,
};

/// Metres per degree of latitude, near enough for one-cell tolerances.
const M_PER_DEG: f64 = 111_320.0;

fn create_costmap(server: &Server, body: &Value) -> String {
    let r = post_json(&server.url("/api/v1/costmaps"), body);
    assert_eq!(r.status, 202, "{}", r.text());
    r.json()["id"].as_str().unwrap().to_string()
}

// ---------------------------------------------------------------- GDAL

/// The costmap as the test sees it: GDAL's reading of its GeoTIFF.
struct Costmap {
    id: String,
    width: usize,
    height: usize,
    /// origin x, cell width, 0, origin y, 0, cell height (negative).
    transform: [f64; 6],
    epsg: u64,
    cost: Vec<f64>,
    class: Vec<f64>,
    /// Traversable region of each cell (-1: not traversable), and the
    /// regions' sizes.
    region: Vec<i64>,
    sizes: Vec<usize>,
}

impl Costmap {
    fn read(server: &Server, dir: &Path, id: &str) -> Costmap {
        let r = get(&server.url(&format!("/api/v1/costmaps/{id}/costmap.tif")));
        assert_eq!(r.status, 200, "{}", r.text());
        let path = dir.join(format!("{id}.tif"));
        std::fs::write(&path, &r.body).unwrap();
        let info = gdalinfo(&path);
        let size = info["size"].as_array().unwrap();
        let (width, height) = (
            size[0].as_u64().unwrap() as usize,
            size[1].as_u64().unwrap() as usize,
        );
        let t: Vec<f64> = info["geoTransform"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let cost = band_values(&path, 1);
        // The class codes are page 2 of the file (Byte, nodata 0 = unknown).
        let class = band_values(&class_page(&path), 1);
        assert_eq!(cost.len(), width * height);
        let (region, sizes) = regions(&cost, width, height);
        Costmap {
            id: id.to_string(),
            width,
            height,
            transform: t.try_into().unwrap(),
            epsg: info["stac"]["proj:epsg"].as_u64().unwrap(),
            cost,
            class,
            region,
            sizes,
        }
    }

    fn traversable(&self, r: usize, c: usize) -> bool {
        self.cost[r * self.width + c].is_finite()
    }

    /// Regions, largest first.
    fn largest_regions(&self) -> Vec<i64> {
        let mut ids: Vec<i64> = (0..self.sizes.len() as i64).collect();
        ids.sort_by_key(|&k| std::cmp::Reverse(self.sizes[k as usize]));
        ids
    }

    /// The cell of region `k` nearest to (row, col).
    fn nearest_in(&self, k: i64, target: (usize, usize)) -> (usize, usize) {
        let d = |r: usize, c: usize| {
            (r as f64 - target.0 as f64).powi(2) + (c as f64 - target.1 as f64).powi(2)
        };
        (0..self.width * self.height)
            .filter(|&i| self.region[i] == k)
            .map(|i| (i / self.width, i % self.width))
            .min_by(|a, b| d(a.0, a.1).total_cmp(&d(b.0, b.1)))
            .expect("a cell of the region")
    }

    /// WGS84 [lon, lat] of cell centres, through gdaltransform.
    fn lonlat(&self, cells: &[(usize, usize)]) -> Vec<[f64; 2]> {
        let t = &self.transform;
        let input: String = cells
            .iter()
            .map(|&(r, c)| {
                let x = t[0] + (c as f64 + 0.5) * t[1];
                let y = t[3] + (r as f64 + 0.5) * t[5];
                format!("{x:.6} {y:.6}\n")
            })
            .collect();
        let s_srs = format!("EPSG:{}", self.epsg);
        let out = run_tool(
            "gdaltransform",
            &["-s_srs", &s_srs, "-t_srs", "EPSG:4326", "-output_xy"],
            Some(&input),
        );
        let lonlat: Vec<[f64; 2]> = out
            .lines()
            .map(|l| {
                let v: Vec<f64> = l.split_whitespace().map(|v| v.parse().unwrap()).collect();
                [v[0], v[1]]
            })
            .collect();
        assert_eq!(lonlat.len(), cells.len(), "{out}");
        lonlat
    }
}

/// Traversable regions of a cost grid as the planner moves: 8-connected,
/// a diagonal step only when both cells beside it are traversable.
fn regions(cost: &[f64], w: usize, h: usize) -> (Vec<i64>, Vec<usize>) {
    let ok = |r: isize, c: isize| {
        r >= 0
            && c >= 0
            && (r as usize) < h
            && (c as usize) < w
            && cost[r as usize * w + c as usize].is_finite()
    };
    let mut label = vec![-1i64; w * h];
    let mut sizes = Vec::new();
    for seed in 0..w * h {
        if label[seed] >= 0 || !cost[seed].is_finite() {
            continue;
        }
        let k = sizes.len() as i64;
        let mut n = 0;
        let mut queue = VecDeque::from([seed]);
        label[seed] = k;
        while let Some(i) = queue.pop_front() {
            n += 1;
            let (r, c) = ((i / w) as isize, (i % w) as isize);
            for dr in -1..=1 {
                for dc in -1..=1 {
                    let (nr, nc) = (r + dr, c + dc);
                    if (dr, dc) == (0, 0) || !ok(nr, nc) {
                        continue;
                    }
                    if dr != 0 && dc != 0 && !(ok(r, nc) && ok(nr, c)) {
                        continue;
                    }
                    let j = nr as usize * w + nc as usize;
                    if label[j] < 0 {
                        label[j] = k;
                        queue.push_back(j);
                    }
                }
            }
        }
        sizes.push(n);
    }
    (label, sizes)
}

// ---------------------------------------------------------------- routes

/// A server, the DTM uploaded and its costmap done.
fn setup(dir: &Path, args: &[&str]) -> (Server, String, Costmap) {
    let server = Server::start(&dir.join("data"), args);
    let dem_id = upload_dem(&server, &dtm());
    let id = create_costmap(&server, &json!({"dem_id": dem_id}));
    let job = wait_costmap_finished(&server, &id);
    assert_eq!(job["status"], "done", "{job}");
    let map = Costmap::read(&server, dir, &id);
    (server, dem_id, map)
}

fn plan(server: &Server, costmap: &str, body: &Value) -> Reply {
    post_json(
        &server.url(&format!("/api/v1/costmaps/{costmap}/routes")),
        body,
    )
}

/// A 201 with its Location: the route.
fn planned(r: &Reply) -> Value {
    assert_eq!(r.status, 201, "{}", r.text());
    let route = r.json();
    let id = route["id"].as_str().expect("id");
    assert_eq!(
        r.header("location"),
        Some(format!("/api/v1/routes/{id}").as_str())
    );
    route
}

fn replan(server: &Server, route: &Value, body: &Value) -> Reply {
    post_json(&server.url(route["urls"]["replan"].as_str().unwrap()), body)
}

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// Metres between two WGS84 points (equirectangular: fine over metres).
fn metres(a: [f64; 2], b: [f64; 2]) -> f64 {
    let k = (a[1].to_radians()).cos();
    ((a[0] - b[0]) * k * M_PER_DEG).hypot((a[1] - b[1]) * M_PER_DEG)
}

fn lonlat_of(p: &Value) -> [f64; 2] {
    [num(&p["lon"]), num(&p["lat"])]
}

/// The waypoint polyline in lon/lat.
fn polyline(route: &Value) -> Vec<Coord<f64>> {
    route["waypoints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| Coord {
            x: num(&p["lon"]),
            y: num(&p["lat"]),
        })
        .collect()
}

fn crosses(route: &Value, area: &Polygon<f64>) -> bool {
    polyline(route)
        .windows(2)
        .any(|s| Line::new(s[0], s[1]).intersects(area))
}

/// A square of half-side `half_m` metres around a WGS84 point, as a
/// polygon and as GeoJSON.
fn square(centre: [f64; 2], half_m: f64) -> (Polygon<f64>, Value) {
    let dlat = half_m / M_PER_DEG;
    let dlon = half_m / (M_PER_DEG * centre[1].to_radians().cos());
    let [x, y] = centre;
    let ring = vec![
        [x - dlon, y - dlat],
        [x + dlon, y - dlat],
        [x + dlon, y + dlat],
        [x - dlon, y + dlat],
        [x - dlon, y - dlat],
    ];
    let polygon = Polygon::new(
        LineString(ring.iter().map(|&[x, y]| Coord { x, y }).collect()),
        vec![],
    );
    (polygon, json!({"type": "Polygon", "coordinates": [ring]}))
}

/// The point halfway along the route's polyline.
fn midpoint(route: &Value) -> [f64; 2] {
    let wp = route["waypoints"].as_array().unwrap();
    let seg: Vec<f64> = wp
        .windows(2)
        .map(|s| metres(lonlat_of(&s[0]), lonlat_of(&s[1])))
        .collect();
    let mut left = seg.iter().sum::<f64>() / 2.0;
    for (i, &len) in seg.iter().enumerate() {
        if left <= len {
            let (a, b) = (lonlat_of(&wp[i]), lonlat_of(&wp[i + 1]));
            let t = left / len;
            return [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
        }
        left -= len;
    }
    unreachable!("the route has a length")
}

/// The route's figures hold together: it starts and ends on the asked
/// cells, is at least as long as the straight line, costs at least its
/// length (every cost is ≥ 1), and its geometry is its waypoints.
fn check_route(route: &Value, start: (usize, usize), goal: (usize, usize), heights: bool) {
    let wp = route["waypoints"].as_array().unwrap();
    assert!(wp.len() >= 2, "{route}");
    let (first, last) = (&wp[0], wp.last().unwrap());
    assert_eq!(
        (first["row"].as_u64(), first["col"].as_u64()),
        (Some(start.0 as u64), Some(start.1 as u64))
    );
    assert_eq!(
        (last["row"].as_u64(), last["col"].as_u64()),
        (Some(goal.0 as u64), Some(goal.1 as u64))
    );
    assert_eq!(route["utm_zone"], "18N");
    assert_eq!(route["utm_epsg"], 32618);
    let straight = (num(&last["easting"]) - num(&first["easting"]))
        .hypot(num(&last["northing"]) - num(&first["northing"]));
    let l2 = num(&route["length_2d_m"]);
    assert!(
        l2 >= straight - 1e-6,
        "2D length {l2} < straight {straight}"
    );
    // The 2D length is the polyline's, as the UTM waypoints give it.
    let poly: f64 = wp
        .windows(2)
        .map(|s| {
            (num(&s[1]["easting"]) - num(&s[0]["easting"]))
                .hypot(num(&s[1]["northing"]) - num(&s[0]["northing"]))
        })
        .sum();
    assert!(close(poly, l2, 1e-3 * l2), "{poly} vs {l2}");
    assert!(num(&route["path_length_m"]) >= l2 - 1e-6);
    assert!(num(&route["cost"]) >= l2 - 1e-6, "cost below length × 1");
    assert!(num(&route["path_cost"]) >= num(&route["path_length_m"]) - 1e-6);
    assert!(
        num(&route["cost"]) <= num(&route["path_cost"]) + 1e-6,
        "smoothing never costs more"
    );
    assert!(route["expanded"].as_u64().is_some());
    assert!(num(&route["search_ms"]) >= 0.0);
    let coords = route["geometry"]["coordinates"].as_array().unwrap();
    assert_eq!(route["geometry"]["type"], "LineString");
    assert_eq!(coords.len(), wp.len());
    // Heights above the WGS 84 ellipsoid (RFC 7946): the terrain's height
    // plus the EGM96 undulation, which PROJ gives independently.
    let undulations = if heights {
        let points: Vec<[f64; 2]> = wp.iter().map(lonlat_of).collect();
        egm96_undulations(&points)
    } else {
        vec![]
    };
    for (i, (c, p)) in coords.iter().zip(wp).enumerate() {
        assert_eq!(c[0], p["lon"]);
        assert_eq!(c[1], p["lat"]);
        if heights {
            assert_eq!(c.as_array().unwrap().len(), 3, "{c}");
            let n = num(&c[2]) - num(&p["height_m"]);
            assert!(
                (n - undulations[i]).abs() <= 0.5,
                "{c}: {n} m above the terrain's height, EGM96 (PROJ) {}",
                undulations[i]
            );
        } else {
            assert_eq!(c.as_array().unwrap().len(), 2, "{c}");
            assert!(p["height_m"].is_null());
        }
    }
    if heights {
        let l3 = num(&route["length_3d_m"]);
        assert!(l3 >= l2 - 1e-9, "3D length {l3} < 2D {l2}");
        assert!(num(&route["climb_m"]) >= 0.0 && num(&route["descent_m"]) >= 0.0);
        let slope = num(&route["max_slope_deg"]);
        assert!((0.0..90.0).contains(&slope));
        assert!(num(&route["mean_slope_deg"]) <= slope);
    } else {
        assert!(route["length_3d_m"].is_null(), "{route}");
    }
}

/// A route of the real DTM from request to files, replanned around a
/// blocked area (the held search repaired, then rebuilt), listed, deleted,
/// and planned again without heights once the DEM is gone.
#[test]
fn route_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    let (server, dem_id, map) = setup(dir.path(), &[]);
    let main = map.largest_regions()[0];
    let (h, w) = (map.height, map.width);
    let start = map.nearest_in(main, (h / 6, w / 6));
    let goal = map.nearest_in(main, (h * 5 / 6, w * 5 / 6));
    let ll = map.lonlat(&[start, goal]);
    let (start_ll, goal_ll) = (ll[0], ll[1]);

    let r = plan(
        &server,
        &map.id,
        &json!({"start": start_ll, "goal": goal_ll, "speed_m_s": 1.5, "name": "across"}),
    );
    let route = planned(&r);
    let id = route["id"].as_str().unwrap().to_string();
    assert_eq!(route["name"], "across");
    assert_eq!(route["costmap_id"], map.id.as_str());
    assert!(route["parent_id"].is_null());
    assert_eq!(
        route["planner"], "astar",
        "a new route: A*, its D* Lite search built after"
    );
    assert_eq!(
        route["options"],
        json!({"arc_cost": {"mode": "integrated"}, "epsilon": 1.0, "smooth": true})
    );
    assert_eq!(route["start"], json!(start_ll));
    assert_eq!(route["speed_m_s"], 1.5);
    assert_eq!(route["blocked"], json!([]));
    check_route(&route, start, goal, true);
    let wp = route["waypoints"].as_array().unwrap().clone();
    // The first and last waypoints are the asked cells' centres.
    assert!(metres(lonlat_of(&wp[0]), start_ll) < 0.1, "{}", wp[0]);
    assert!(metres(lonlat_of(wp.last().unwrap()), goal_ll) < 0.1);
    assert!(metres(lonlat_of(&wp[0]), start_ll) < 2.0, "within one cell");
    // A search of the whole region, at least.
    let expanded = route["expanded"].as_u64().unwrap();
    assert!(expanded > 1000, "{expanded}");
    // Every waypoint is on a traversable cell; the heights are the DEM's
    // (the costmap keeps the DEM's 2 m grid).
    let cells: Vec<(usize, usize)> = wp
        .iter()
        .map(|p| {
            (
                p["row"].as_u64().unwrap() as usize,
                p["col"].as_u64().unwrap() as usize,
            )
        })
        .collect();
    for &(r, c) in &cells {
        assert!(map.traversable(r, c), "waypoint on ({r}, {c})");
    }
    let pixels: Vec<(usize, usize)> = cells.iter().map(|&(r, c)| (c, r)).collect();
    for (p, z) in wp.iter().zip(pixel_values(&dtm(), 1, &pixels)) {
        assert!(close(num(&p["height_m"]), z, 1e-3), "{p} vs DEM {z}");
    }
    let base = format!("/api/v1/routes/{id}");
    assert_eq!(route["urls"]["self"], base.as_str());
    assert_eq!(route["urls"]["geojson"], format!("{base}/route.geojson"));
    assert_eq!(route["urls"]["csv"], format!("{base}/route.csv"));
    assert_eq!(
        route["urls"]["waypoints"],
        format!("{base}/mission.waypoints")
    );
    assert_eq!(route["urls"]["replan"], format!("{base}/replan"));
    let r = get(&server.url(&base));
    assert_eq!(r.status, 200);
    assert_eq!(r.json(), route);

    // Files.
    let r = get(&server.url(&format!("{base}/route.geojson")));
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.header("content-type"), Some("application/geo+json"));
    assert!(
        r.header("content-disposition")
            .unwrap()
            .starts_with("attachment")
    );
    // A FeatureCollection like a survey's route files; heights above the
    // WGS 84 ellipsoid, the terrain's as properties.
    let collection = r.json();
    assert_eq!(collection["type"], "FeatureCollection");
    assert_eq!(collection["features"].as_array().unwrap().len(), 1);
    let feature = &collection["features"][0];
    assert_eq!(feature["type"], "Feature");
    assert_eq!(feature["geometry"], route["geometry"]);
    let props = &feature["properties"];
    assert_eq!(props["id"], id.as_str());
    assert!(
        props["height_reference"]
            .as_str()
            .unwrap()
            .starts_with("WGS 84 ellipsoid"),
        "{props}"
    );
    // The terrain's heights, to the millimetre.
    let terrain = props["terrain_heights_m"].as_array().unwrap();
    assert_eq!(terrain.len(), wp.len());
    for (t, p) in terrain.iter().zip(&wp) {
        assert!((num(t) - num(&p["height_m"])).abs() <= 0.0005, "{t} vs {p}");
    }
    let points: Vec<[f64; 2]> = wp.iter().map(lonlat_of).collect();
    let coords = feature["geometry"]["coordinates"].as_array().unwrap();
    for ((c, n), proj_n) in coords
        .iter()
        .zip(props["egm96_undulations_m"].as_array().unwrap())
        .zip(egm96_undulations(&points))
    {
        assert_eq!(c.as_array().unwrap().len(), 3, "{c}");
        assert!((num(n) - proj_n).abs() <= 0.5, "{n} vs PROJ's {proj_n}");
    }
    let r = get(&server.url(&format!("{base}/route.csv")));
    assert_eq!(r.status, 200);
    assert!(r.header("content-type").unwrap().starts_with("text/csv"));
    let csv = r.text();
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows[0], "index,easting,northing,zone,height");
    assert_eq!(rows.len(), wp.len() + 1);
    for (i, (row, p)) in rows[1..].iter().zip(&wp).enumerate() {
        let f: Vec<&str> = row.split(',').collect();
        assert_eq!(f.len(), 5, "{row}");
        assert_eq!(f[0], i.to_string());
        assert!(
            close(f[1].parse().unwrap(), num(&p["easting"]), 1e-3),
            "{row}"
        );
        assert!(
            close(f[2].parse().unwrap(), num(&p["northing"]), 1e-3),
            "{row}"
        );
        assert_eq!(f[3], "18N");
        assert!(
            close(f[4].parse().unwrap(), num(&p["height_m"]), 1e-3),
            "{row}"
        );
    }
    let r = get(&server.url(&format!("{base}/mission.waypoints")));
    assert_eq!(r.status, 200);
    assert!(r.header("content-type").unwrap().starts_with("text/plain"));
    assert!(
        r.header("content-disposition")
            .unwrap()
            .contains(".waypoints")
    );
    let path = dir.path().join("route.waypoints");
    std::fs::write(&path, &r.body).unwrap();
    let loaded = validator("load_waypoints.py", &[&path]);
    assert!(loaded.status.success(), "{}", text(&loaded.stderr));
    let loaded: Value = serde_json::from_slice(&loaded.stdout).unwrap();
    let items = loaded["items"].as_array().unwrap();
    // Home, the speed, then a NAV_WAYPOINT for every waypoint but the start.
    assert_eq!(loaded["count"].as_u64(), Some(wp.len() as u64 + 1));
    let home = &items[0];
    assert_eq!(home["command"], 16);
    assert!(
        close(num(&home["lat"]), start_ll[1], 1e-7) && close(num(&home["lon"]), start_ll[0], 1e-7),
        "{home}"
    );
    assert!(close(num(&home["alt"]), num(&wp[0]["height_m"]), 1e-3));
    assert_eq!(items[1]["command"], 178);
    assert!(close(num(&items[1]["params"][1]), 1.5, 1e-9));
    let nav: Vec<&Value> = items[2..].iter().collect();
    assert!(nav.iter().all(|i| i["command"] == 16));
    for (item, p) in nav.iter().zip(&wp[1..]) {
        assert!(close(num(&item["lat"]), num(&p["lat"]), 1e-7), "{item}");
        assert!(close(num(&item["lon"]), num(&p["lon"]), 1e-7), "{item}");
    }
    let last = nav.last().unwrap();
    assert!(
        close(num(&last["lat"]), goal_ll[1], 1e-7) && close(num(&last["lon"]), goal_ll[0], 1e-7)
    );

    // Replan from the start after a square across the middle of the route
    // is found blocked: the held D* Lite search is repaired.
    let (area, area_json) = square(midpoint(&route), 8.0);
    assert!(
        crosses(&route, &area),
        "the first route runs through the area"
    );
    let body = json!({"position": start_ll, "blocked": [area_json]});
    let second = planned(&replan(&server, &route, &body));
    assert_eq!(second["parent_id"], id.as_str());
    assert_eq!(second["urls"]["parent"], base.as_str());
    assert_eq!(second["name"], "across", "the parent's name");
    assert_eq!(second["planner"], "dstar_lite");
    assert_eq!(second["reused_search"], true);
    assert_eq!(second["goal"], route["goal"]);
    assert_eq!(second["options"], route["options"]);
    assert_eq!(second["blocked"].as_array().unwrap().len(), 1);
    check_route(&second, start, goal, true);
    assert_ne!(second["geometry"], route["geometry"]);
    assert!(
        !crosses(&second, &area),
        "the replan crosses the blocked area"
    );
    assert!(
        num(&second["path_cost"]) >= num(&route["path_cost"]) - 1e-9,
        "blocking made the route cheaper"
    );
    assert!(num(&second["path_cost"]) > num(&route["path_cost"]));

    // Driving on, the robot finds the ground just ahead costlier: the
    // second replan repairs the search again, expanding far fewer cells
    // than a search from scratch. (D* Lite searches back from the goal,
    // so changes near the robot are cheap to repair.)
    let wp2 = second["waypoints"].as_array().unwrap();
    let here = wp2[2].clone();
    let here_cell = (
        here["row"].as_u64().unwrap() as usize,
        here["col"].as_u64().unwrap() as usize,
    );
    let (_, patch) = square(lonlat_of(&wp2[5]), 4.0);
    let third = planned(&replan(
        &server,
        &second,
        &json!({"position": [here["lon"], here["lat"]], "cost_changes": [{"area": patch, "cost": 20}], "name": "third"}),
    ));
    assert_eq!(third["parent_id"], second["id"]);
    assert_eq!(third["name"], "third");
    assert_eq!(third["planner"], "dstar_lite");
    assert_eq!(third["reused_search"], true);
    assert!(
        third["expanded"].as_u64().unwrap() < expanded,
        "{} vs {expanded}",
        third["expanded"]
    );
    assert_eq!(
        third["blocked"], second["blocked"],
        "blocked areas are cumulative"
    );
    assert_eq!(third["cost_changes"].as_array().unwrap().len(), 1);
    assert_eq!(third["cost_changes"][0]["cost"], 20.0);
    check_route(&third, here_cell, goal, true);
    assert!(!crosses(&third, &area));

    // The first route's search moved on to the second: replanning from
    // the first again rebuilds it from the costmap, to the same optimum.
    let again = planned(&replan(&server, &route, &body));
    assert_eq!(again["reused_search"], false);
    assert_eq!(again["planner"], "dstar_lite");
    assert!(again["expanded"].as_u64().unwrap() > third["expanded"].as_u64().unwrap());
    let (a, b) = (num(&again["path_cost"]), num(&second["path_cost"]));
    assert!(close(a, b, 1e-9 * b), "rebuilt {a} vs repaired {b}");
    assert!(!crosses(&again, &area));

    // Weighted A*: its own planner, and replans from scratch.
    let fast = planned(&plan(
        &server,
        &map.id,
        &json!({"start": start_ll, "goal": goal_ll, "epsilon": 2, "arc_cost": {"mode": "thesis"}}),
    ));
    assert_eq!(fast["planner"], "astar");
    assert_eq!(
        fast["options"]["arc_cost"],
        json!({"mode": "thesis", "d_max": 10.0})
    );
    check_route(&fast, start, goal, true);
    let fast_replan = planned(&replan(&server, &fast, &body));
    assert_eq!(fast_replan["planner"], "astar");
    assert_eq!(fast_replan["reused_search"], false);
    assert!(!crosses(&fast_replan, &area));

    // Listing, newest first, by costmap.
    let r = get(&server.url(&format!("/api/v1/routes?costmap_id={}&limit=3", map.id)));
    assert_eq!(r.status, 200, "{}", r.text());
    let list = r.json();
    assert_eq!(list["total"], 6);
    let ids: Vec<&Value> = list["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| &i["id"])
        .collect();
    assert_eq!(ids, [&fast_replan["id"], &fast["id"], &again["id"]]);
    let r = get(&server.url("/api/v1/routes?costmap_id=nope"));
    assert_eq!(r.json()["total"], 0);
    assert_problem(&get(&server.url("/api/v1/routes?limit=0")), 400, "limit");

    // Delete: gone with its files; its replans stay.
    let third_url = third["urls"]["self"].as_str().unwrap().to_string();
    assert_eq!(delete(&server.url(&third_url)).status, 204);
    assert_problem(&get(&server.url(&third_url)), 404, "no route");
    assert_problem(&delete(&server.url(&third_url)), 404, "no route");
    assert_problem(
        &get(&server.url(&format!("{third_url}/route.csv"))),
        404,
        "no route",
    );
    assert_problem(
        &replan(&server, &third, &json!({"position": start_ll})),
        404,
        "no route",
    );
    assert_eq!(get(&server.url(&base)).status, 200);

    // Without the DEM: routes without heights.
    assert_eq!(
        delete(&server.url(&format!("/api/v1/dems/{dem_id}"))).status,
        204
    );
    let flat = planned(&plan(
        &server,
        &map.id,
        &json!({"start": start_ll, "goal": goal_ll}),
    ));
    check_route(&flat, start, goal, false);
    assert!(close(
        num(&flat["path_cost"]),
        num(&route["path_cost"]),
        1e-9 * num(&route["path_cost"])
    ));
    let r = get(&server.url(flat["urls"]["waypoints"].as_str().unwrap()));
    assert_eq!(r.status, 200);

    // Deleting the costmap deletes its routes.
    assert_eq!(
        delete(&server.url(&format!("/api/v1/costmaps/{}", map.id))).status,
        204
    );
    assert_problem(&get(&server.url(&base)), 404, "no route");
    let r = get(&server.url(&format!("/api/v1/routes?costmap_id={}", map.id)));
    assert_eq!(r.json()["total"], 0);
}

/// Faults of route and replan requests: 422s naming the member by JSON
/// pointer (outside, on an obstacle, unreachable, options, polygons,
/// costs), 400/415 for malformed bodies, 404 for unknown resources.
#[test]
fn route_request_faults() {
    let dir = tempfile::tempdir().unwrap();
    let (server, _, map) = setup(dir.path(), &[]);
    let ids = map.largest_regions();
    let (main, other) = (ids[0], ids[1]);
    let (h, w) = (map.height, map.width);
    let start = map.nearest_in(main, (h / 2, w / 2));
    let goal = map.nearest_in(main, (h * 5 / 6, w * 5 / 6));
    let island = map.nearest_in(other, (0, 0));
    // An obstacle cell (a step, class 3) inside the map.
    let obstacle = (h / 4..h * 3 / 4)
        .flat_map(|r| (w / 4..w * 3 / 4).map(move |c| (r, c)))
        .find(|&(r, c)| map.class[r * w + c] == 3.0)
        .expect("a step obstacle");
    assert!(!map.traversable(obstacle.0, obstacle.1));
    let ll = map.lonlat(&[start, goal, island, obstacle]);
    let (s, g, isl, obs) = (ll[0], ll[1], ll[2], ll[3]);
    let url = |body: &Value| plan(&server, &map.id, body);

    let r = url(&json!({"start": [s[0] - 0.01, s[1]], "goal": g}));
    assert_invalid_at(&r, "start outside", "/start", "the start");
    assert_problem(&r, 422, "outside the costmap");
    let r = url(&json!({"start": s, "goal": obs}));
    assert_invalid_at(&r, "goal on a step", "/goal", "on an obstacle (a step");
    let r = url(&json!({"start": s, "goal": isl}));
    assert_invalid_at(&r, "unreachable", "/goal", "different traversable regions");
    let r = url(&json!({"start": obs, "goal": [g[0] + 0.02, g[1]]}));
    let p = assert_problem(&r, 422, "the start");
    assert_eq!(p["errors"].as_array().unwrap().len(), 2, "both ends: {p}");
    let r = url(&json!({"start": s, "goal": g, "epsilon": 0.5}));
    assert_invalid_at(&r, "epsilon", "/epsilon", "epsilon must be in [1, 10]");
    let r = url(&json!({"start": s, "goal": g, "arc_cost": {"mode": "thesis", "d_max": 0.5}}));
    assert_invalid_at(&r, "d_max", "/arc_cost/d_max", "d_max must be in");
    let r = url(&json!({"start": s, "goal": g, "arc_cost": {"mode": "mcp"}}));
    assert_invalid_at(&r, "arc mode", "/arc_cost/mode", "mcp");
    let r = url(&json!({"start": s, "goal": g, "max_expansions": 5}));
    assert_invalid_at(&r, "unknown field", "/max_expansions", "unknown field");
    let r = url(&json!({"start": [s[0], 95.0], "goal": {"utm": "x"}, "speed_m_s": -1}));
    assert_invalid_at(&r, "latitude", "/start", "lat in [-90, 90]");
    assert_invalid_at(&r, "utm", "/goal/utm", "easting, northing");
    assert_invalid_at(&r, "speed", "/speed_m_s", "speed_m_s must be in");
    let r = url(&json!({"goal": g}));
    assert_invalid_at(&r, "no start", "/start", "required");
    let costmap_routes = server.url(&format!("/api/v1/costmaps/{}/routes", map.id));
    assert_problem(
        &post(&costmap_routes, "application/json", b"{\"start\": "),
        400,
        "not valid JSON",
    );
    assert_problem(
        &post(&costmap_routes, "text/plain", b"{}"),
        415,
        "application/json",
    );
    assert_problem(
        &post_json(
            &server.url("/api/v1/costmaps/nope/routes"),
            &json!({"start": s, "goal": g}),
        ),
        404,
        "no costmap",
    );
    assert_problem(&get(&server.url("/api/v1/routes/nope")), 404, "no route");
    assert_problem(
        &get(&server.url("/api/v1/routes/nope/mission.waypoints")),
        404,
        "no route",
    );
    assert_problem(
        &post_json(
            &server.url("/api/v1/routes/nope/replan"),
            &json!({"position": s}),
        ),
        404,
        "no route",
    );

    // UTM positions: the same route as lon/lat.
    let route = planned(&url(&json!({"start": s, "goal": g})));
    let first = &route["waypoints"][0];
    let by_utm = planned(&url(&json!({
        "start": {"utm": [first["easting"], first["northing"]]},
        "goal": g,
    })));
    assert_eq!(by_utm["waypoints"][0]["row"], first["row"]);
    assert_eq!(by_utm["waypoints"][0]["col"], first["col"]);
    assert!(close(
        num(&by_utm["path_cost"]),
        num(&route["path_cost"]),
        1e-9 * num(&route["path_cost"])
    ));

    // Replan faults.
    let re = |body: &Value| replan(&server, &route, body);
    let r = re(&json!({"position": [s[0] - 0.01, s[1]]}));
    assert_invalid_at(&r, "position outside", "/position", "the position");
    let r = re(&json!({"position": obs}));
    assert_invalid_at(&r, "position on a step", "/position", "on an obstacle");
    let bowtie = json!({"type": "Polygon", "coordinates": [[[s[0], s[1]], [s[0] + 1e-4, s[1] + 1e-4], [s[0] + 1e-4, s[1]], [s[0], s[1] + 1e-4], [s[0], s[1]]]]});
    let (_, ok_area) = square(s, 3.0);
    let r = re(&json!({
        "position": s,
        "blocked": [ok_area, bowtie, {"type": "Point", "coordinates": s}],
        "cost_changes": [{"area": ok_area, "cost": 0}, {"area": ok_area, "cost": 2, "when": 1}, {"cost": 2}],
    }));
    let p = assert_problem(&r, 422, "self-intersects");
    let pointers: Vec<&str> = p["errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["pointer"].as_str().unwrap())
        .collect();
    for prefix in [
        "/blocked/1",
        "/blocked/2",
        "/cost_changes/0/cost",
        "/cost_changes/1/when",
        "/cost_changes/2/area",
    ] {
        assert!(
            pointers.iter().any(|p| p.starts_with(prefix)),
            "{prefix} not in {pointers:?}"
        );
    }
    assert!(
        !pointers.iter().any(|p| p.starts_with("/blocked/0")),
        "{pointers:?}"
    );
    let r = re(&json!({"position": s, "cost_changes": [{"area": ok_area, "cost": f64::MAX}]}));
    assert_invalid_at(&r, "huge cost", "/cost_changes/0/cost", "(0, 1000000]");
    let r = re(&json!({"position": s, "blocked": [ok_area]}));
    assert_invalid_at(
        &r,
        "position blocked",
        "/position",
        "inside an area this replan blocks",
    );
    let (_, over_goal) = square(g, 3.0);
    let (_, between) = square([(s[0] + g[0]) / 2.0, (s[1] + g[1]) / 2.0], 3.0);
    let r = re(&json!({"position": s, "blocked": [between, over_goal]}));
    assert_invalid_at(&r, "goal blocked", "/blocked/1", "covers the route's goal");
    // None of these touched the route's held search: a replan repairs it
    // (here with no change at all: the same optimum).
    let fine = planned(&re(&json!({"position": s})));
    assert_eq!(fine["reused_search"], true, "{fine}");
    assert!(close(
        num(&fine["path_cost"]),
        num(&route["path_cost"]),
        1e-9 * num(&route["path_cost"])
    ));
    // A ring around the goal cuts it off.
    let ring = {
        let (outer, _) = square(g, 30.0);
        let (inner, _) = square(g, 20.0);
        let pts = |p: &Polygon<f64>| -> Vec<[f64; 2]> {
            p.exterior().0.iter().map(|c| [c.x, c.y]).collect()
        };
        let mut hole = pts(&inner);
        hole.reverse();
        json!({"type": "Polygon", "coordinates": [pts(&outer), hole]})
    };
    let r = replan(&server, &fine, &json!({"position": s, "blocked": [ring]}));
    assert_invalid_at(&r, "goal cut off", "/blocked", "the goal cannot be reached");
    // The failed search was undone and kept: the next replan repairs it.
    let after = planned(&replan(&server, &fine, &json!({"position": s})));
    assert_eq!(after["reused_search"], true, "{after}");
    assert!(close(
        num(&after["path_cost"]),
        num(&route["path_cost"]),
        1e-9 * num(&route["path_cost"])
    ));
    // A position inside an area an earlier replan blocked (the first
    // replan drives to the goal: a route of one waypoint).
    let (_, near_start) = square(s, 6.0);
    let one = planned(&re(&json!({"position": g, "blocked": [near_start]})));
    assert_eq!(one["waypoints"].as_array().unwrap().len(), 1);
    assert_eq!(one["geometry"]["coordinates"].as_array().unwrap().len(), 2);
    let r = replan(&server, &one, &json!({"position": s}));
    assert_invalid_at(
        &r,
        "earlier block",
        "/position",
        "an earlier replan blocked",
    );
}

/// Routes need a done costmap (409 naming the status), and a search over
/// the time limit is stopped with a 503.
#[test]
fn unfinished_costmaps_and_the_time_limit() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(
        &dir.path().join("data"),
        &["--costmap-jobs", "1", "--route-timeout-s", "0.001"],
    );
    let dem_id = upload_dem(&server, &dtm());
    let other_dem = upload_dem(&server, &dtm());
    let blocker = create_costmap(
        &server,
        &json!({"dem_id": dem_id, "options": slow_costmap_options()}),
    );
    let doomed = create_costmap(&server, &json!({"dem_id": other_dem}));
    let body = json!({"start": [-77.054, 38.811], "goal": [-77.051, 38.809]});
    // The slow job holds the only slot for seconds: the other is queued.
    let r = plan(&server, &doomed, &body);
    let p = assert_problem(&r, 409, "queued");
    assert!(
        p["detail"]
            .as_str()
            .unwrap()
            .contains("once its status is done"),
        "{p}"
    );
    let r = plan(&server, &blocker, &body);
    if r.status == 409 {
        let p = assert_problem(&r, 409, "costmap");
        let detail = p["detail"].as_str().unwrap();
        assert!(
            detail.contains("still running (") || detail.contains("is queued"),
            "{detail}"
        );
    }
    // Its DEM gone before it runs, the queued job fails.
    assert_eq!(
        delete(&server.url(&format!("/api/v1/dems/{other_dem}"))).status,
        204
    );
    assert_eq!(wait_costmap_finished(&server, &doomed)["status"], "failed");
    assert_problem(&plan(&server, &doomed, &body), 409, "failed");
    assert_eq!(wait_costmap_finished(&server, &blocker)["status"], "done");

    // A search across the map takes more than a millisecond.
    let map = Costmap::read(&server, dir.path(), &blocker);
    let main = map.largest_regions()[0];
    let (h, w) = (map.height, map.width);
    let ll = map.lonlat(&[
        map.nearest_in(main, (h / 6, w / 6)),
        map.nearest_in(main, (h * 5 / 6, w * 5 / 6)),
    ]);
    let r = plan(&server, &blocker, &json!({"start": ll[0], "goal": ll[1]}));
    assert_problem(&r, 503, "took too long");
    assert!(r.header("retry-after").is_some());
    assert_eq!(get(&server.url("/healthz")).status, 200);
}

#[test]
fn routes_in_the_openapi_document() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let doc = get(&server.url("/api/v1/openapi.json")).json();
    let paths = doc["paths"].as_object().unwrap();
    for (path, methods) in [
        ("/api/v1/costmaps/{id}/routes", &["post"][..]),
        ("/api/v1/routes", &["get"]),
        ("/api/v1/routes/{id}", &["get", "delete"]),
        ("/api/v1/routes/{id}/replan", &["post"]),
        ("/api/v1/routes/{id}/route.geojson", &["get"]),
        ("/api/v1/routes/{id}/route.csv", &["get"]),
        ("/api/v1/routes/{id}/mission.waypoints", &["get"]),
    ] {
        for m in methods {
            let op = &paths[path][m];
            assert!(
                op.is_object(),
                "{m} {path} missing from the OpenAPI document"
            );
            assert_eq!(op["tags"], json!(["routes"]), "{m} {path}");
        }
    }
    let post = &paths["/api/v1/costmaps/{id}/routes"]["post"];
    for status in ["201", "404", "409", "422", "503"] {
        assert!(post["responses"][status].is_object(), "{status}");
    }
    let schemas = &doc["components"]["schemas"];
    assert_eq!(
        schemas["Planner"]["enum"],
        json!(["dstar_lite", "astar", "coarse_to_fine"])
    );
    for s in [
        "CreateRoute",
        "ReplanRoute",
        "RouteResponse",
        "RouteList",
        "MapRoute",
        "RoutePoint",
        "Position",
        "ArcCost",
        "CostChange",
    ] {
        assert!(schemas[s].is_object(), "schema {s} missing");
    }
    for field in [
        "start",
        "goal",
        "arc_cost",
        "epsilon",
        "smooth",
        "speed_m_s",
        "name",
    ] {
        assert!(
            schemas["CreateRoute"]["properties"][field].is_object(),
            "{field}"
        );
    }
}
