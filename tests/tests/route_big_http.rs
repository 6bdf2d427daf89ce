//! Routes on big costmaps through the service (issue 22 item 3): a costmap
//! of more cells than `--route-coarse-cells`, or whose search in memory
//! would not fit the memory budget, is planned coarse to fine, its GeoTIFF
//! read a window at a time from the database. On a shared DEM's costmap
//! the route equals plain A*'s (the same cells, the cost within 1e-9
//! relative) and says it is proven optimal; a budget too small for plain
//! A* routes instead of refusing; replans of such routes are refused by
//! name.

use std::path::Path;

use serde_json::{Value, json};
use terraplan_e2e::{
    Server, assert_invalid_at, band_values, gdalinfo, get, post_json, run_tool, shared_data,
    upload_dem, wait_costmap_finished,
};

/// The costmap as the test picks endpoints on it: its size, geotransform
/// and costs (GDAL's reading of the served GeoTIFF).
struct Costmap {
    width: usize,
    height: usize,
    transform: Vec<f64>,
    cost: Vec<f64>,
}

impl Costmap {
    fn read(server: &Server, dir: &Path, id: &str) -> Costmap {
        let r = get(&server.url(&format!("/api/v1/costmaps/{id}/costmap.tif")));
        assert_eq!(r.status, 200, "{}", r.text());
        let path = dir.join("costmap.tif");
        std::fs::write(&path, &r.body).unwrap();
        let info = gdalinfo(&path);
        let size = info["size"].as_array().unwrap();
        Costmap {
            width: size[0].as_u64().unwrap() as usize,
            height: size[1].as_u64().unwrap() as usize,
            transform: info["geoTransform"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect(),
            cost: band_values(&path, 1),
        }
    }

    /// The largest 4-connected region of traversable cells (any two of
    /// its cells are joined by a route).
    fn largest_region(&self) -> Vec<bool> {
        let (w, h) = (self.width, self.height);
        let free = |i: usize| self.cost[i].is_finite() && self.cost[i] > 0.0;
        let mut label = vec![usize::MAX; w * h];
        let (mut best, mut best_size) = (usize::MAX, 0);
        for seed in 0..w * h {
            if !free(seed) || label[seed] != usize::MAX {
                continue;
            }
            label[seed] = seed;
            let (mut stack, mut size) = (vec![seed], 0);
            while let Some(i) = stack.pop() {
                size += 1;
                let (r, c) = (i / w, i % w);
                let next = [
                    (r > 0).then(|| i - w),
                    (r + 1 < h).then(|| i + w),
                    (c > 0).then(|| i - 1),
                    (c + 1 < w).then(|| i + 1),
                ];
                for j in next.into_iter().flatten() {
                    if free(j) && label[j] == usize::MAX {
                        label[j] = seed;
                        stack.push(j);
                    }
                }
            }
            if size > best_size {
                (best, best_size) = (seed, size);
            }
        }
        label.iter().map(|&l| l == best).collect()
    }

    /// The cell of `region` nearest (row, col), and its position: UTM
    /// easting and northing of the cell centre (the costmap is in the UTM
    /// zone of its centre).
    fn position_near(&self, region: &[bool], row: usize, col: usize) -> (usize, usize, Value) {
        let w = self.width;
        let i = (0..region.len())
            .filter(|&i| region[i])
            .min_by_key(|&i| (i / w).abs_diff(row).pow(2) + (i % w).abs_diff(col).pow(2))
            .expect("a traversable region");
        let (r, c) = (i / w, i % w);
        let t = &self.transform;
        let (x, y) = (
            t[0] + (c as f64 + 0.5) * t[1],
            t[3] + (r as f64 + 0.5) * t[5],
        );
        (r, c, json!({"utm": [x, y]}))
    }
}

fn plan(server: &Server, costmap: &str, body: &Value) -> terraplan_e2e::Reply {
    post_json(
        &server.url(&format!("/api/v1/costmaps/{costmap}/routes")),
        body,
    )
}

fn cells(route: &Value) -> Vec<(u64, u64)> {
    route["waypoints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p["row"].as_u64().unwrap(), p["col"].as_u64().unwrap()))
        .collect()
}

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("{v} is not a number"))
}

#[test]
fn big_costmaps_are_routed_coarse_to_fine_through_the_api() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    // Plain A* first (the default threshold, the default budget).
    let server = Server::start(&data, &[]);
    // The DTM of the route tests three times finer (849 × 777 cells).
    let dem = dir.path().join("dtm3.tif");
    run_tool(
        "gdal_translate",
        &[
            "-q",
            "-outsize",
            "300%",
            "300%",
            "-r",
            "bilinear",
            shared_data("dems/opengeos_data__elevation_dtm.tif")
                .to_str()
                .unwrap(),
            dem.to_str().unwrap(),
        ],
        None,
    );
    let dem_id = upload_dem(&server, &dem);
    let r = post_json(&server.url("/api/v1/costmaps"), &json!({"dem_id": dem_id}));
    assert_eq!(r.status, 202, "{}", r.text());
    let costmap = r.json()["id"].as_str().unwrap().to_string();
    let job = wait_costmap_finished(&server, &costmap);
    assert_eq!(job["status"], "done", "{job}");
    let map = Costmap::read(&server, dir.path(), &costmap);
    let (w, h) = (map.width, map.height);
    assert!(w * h > 400_000, "{w} × {h}");
    // Corner to corner, across the middle, and a short hop, in the
    // largest region.
    let region = map.largest_region();
    let at = |r, c| map.position_near(&region, r, c);
    let pairs = [
        (at(h / 20, w / 20), at(h - h / 20, w - w / 20)),
        (at(h / 2, 2), at(h / 3, w - 30)),
        (at(h / 2, w / 2), at(h / 2 + 40, w / 2 + 25)),
    ];
    let body = |s: &Value, g: &Value| json!({"start": s, "goal": g, "smooth": false});
    let plain: Vec<Value> = pairs
        .iter()
        .map(|((.., s), (.., g))| {
            let r = plan(&server, &costmap, &body(s, g));
            assert_eq!(r.status, 201, "{}", r.text());
            let route = r.json();
            assert_eq!(route["planner"], "astar", "{route}");
            assert!(route.get("search").is_none(), "no search entry for A*");
            route
        })
        .collect();
    drop(server);

    // Coarse to fine: the same routes, proven optimal.
    let server = Server::start(&data, &["--route-coarse-cells", "1000"]);
    for (i, ((s, g), a)) in pairs.iter().zip(&plain).enumerate() {
        let r = plan(&server, &costmap, &body(&s.2, &g.2));
        assert_eq!(r.status, 201, "pair {i}: {}", r.text());
        let route = r.json();
        assert_eq!(route["planner"], "coarse_to_fine", "{route}");
        let search = &route["search"];
        assert_eq!(search["method"], "coarse_to_fine", "{search}");
        assert_eq!(search["proven_optimal"], true, "pair {i}: {search}");
        assert_eq!(num(&search["gap"]), 0.0);
        assert!(num(&search["stats"]["corridors"]) >= 1.0, "{search}");
        let (x, y) = (num(&a["path_cost"]), num(&route["path_cost"]));
        assert!(
            (x - y).abs() <= 1e-9 * x,
            "pair {i}: A* {x} vs coarse to fine {y}"
        );
        assert_eq!(num(&search["lower_bound"]), y);
        assert_eq!(route["path_cells"], a["path_cells"], "pair {i}");
        assert_eq!(cells(&route), cells(a), "pair {i}: the same turning points");
        assert_eq!(cells(&route)[0], (s.0 as u64, s.1 as u64));
        // Heights from the DEM's stored tiles, read by windows: the same
        // as from the DEM read whole.
        let heights = |r: &Value| -> Vec<Value> {
            r["waypoints"]
                .as_array()
                .unwrap()
                .iter()
                .map(|p| p["height_m"].clone())
                .collect()
        };
        assert!(heights(&route).iter().all(Value::is_number), "{route}");
        assert_eq!(heights(&route), heights(a), "pair {i}");
        for key in [
            "length_3d_m",
            "climb_m",
            "descent_m",
            "max_slope_deg",
            "mean_slope_deg",
        ] {
            let (x, y) = (num(&a[key]), num(&route[key]));
            assert!(
                (x - y).abs() <= 1e-9 * x.abs().max(1.0),
                "pair {i}: {key} {x} vs {y}"
            );
        }
        let stored = get(&server.url(&format!("/api/v1/routes/{}", route["id"].as_str().unwrap())));
        assert_eq!(stored.json()["search"], *search, "kept with the route");
        if i == 0 {
            // Its replans are refused by name.
            let r = post_json(
                &server.url(&format!(
                    "/api/v1/routes/{}/replan",
                    route["id"].as_str().unwrap()
                )),
                &json!({"position": s.2, "blocked": []}),
            );
            assert_invalid_at(&r, "replan", "", "planned coarse to fine");
            // So is a weighted search.
            let mut weighted = body(&s.2, &g.2);
            weighted["epsilon"] = json!(1.5);
            let r = plan(&server, &costmap, &weighted);
            assert_invalid_at(&r, "epsilon", "/epsilon", "epsilon must be 1");
        }
    }
    // The search entry is in the OpenAPI document, optional.
    let doc = get(&server.url("/api/v1/openapi.json")).json();
    let schemas = &doc["components"]["schemas"];
    // (Its own members are the part of its allOf beside MapRoute's.)
    let response = schemas["RouteResponse"]["allOf"]
        .as_array()
        .unwrap()
        .iter()
        .find(|part| part["properties"].is_object())
        .expect("RouteResponse's own members");
    assert!(response["properties"]["search"].is_object(), "{response}");
    assert!(
        !response["required"]
            .as_array()
            .unwrap()
            .contains(&json!("search")),
        "search is optional"
    );
    for field in ["method", "proven_optimal", "lower_bound", "gap", "stats"] {
        assert!(
            schemas["SearchReport"]["properties"][field].is_object(),
            "SearchReport.{field}: {}",
            schemas["SearchReport"]
        );
    }
    assert!(schemas["CoarseToFineStats"]["properties"]["corridors"].is_object());
    // Endpoint faults are named as for A*.
    let t = &map.transform;
    let outside = json!({"utm": [t[0] - 10.0, t[3] + 10.0]});
    let r = plan(&server, &costmap, &body(&outside, &pairs[0].1.2));
    assert_invalid_at(&r, "outside", "/start", "outside");
    drop(server);

    // A memory budget too small for A* in memory: routed coarse to fine,
    // within the bound it reports.
    let server = Server::start(&data, &["--memory-budget-mb", "48"]);
    let ((_, _, s), (_, _, g)) = &pairs[0];
    let r = plan(&server, &costmap, &body(s, g));
    assert_eq!(r.status, 201, "{}", r.text());
    let route = r.json();
    assert_eq!(route["planner"], "coarse_to_fine", "{route}");
    let optimum = num(&plain[0]["path_cost"]);
    let cost = num(&route["path_cost"]);
    let bound = num(&route["search"]["lower_bound"]);
    eprintln!("within a budget of 48 MiB: {}", route["search"]);
    assert!(
        cost >= optimum * (1.0 - 1e-9),
        "{cost} < the optimum {optimum}"
    );
    assert!(
        bound <= optimum * (1.0 + 1e-9),
        "bound {bound} > the optimum {optimum}"
    );
    if route["search"]["proven_optimal"] == true {
        assert!((cost - optimum).abs() <= 1e-9 * optimum);
    }
}
