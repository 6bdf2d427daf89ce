//! Reading the bodies of `POST /api/v1/costmaps/{id}/routes` and
//! `POST /api/v1/routes/{id}/replan`: every fault named by JSON pointer,
//! areas counted against the limits before any is checked.

use geo::{CoordsIter, Orient, orient::Direction};
use geo_types::{LineString, Polygon};
use planner_core::geo::{
    Issue, Limits, MAX_ISSUES, deserialize_at, escape_pointer_token, parse_polygons, polygon_issues,
};
use planner_core::route::{ArcCost, Position};
use serde_json::{Map, Value, json};

use super::model::{Changes, SearchOptions};
use crate::api::names::read_name;
use crate::error::ApiError;

/// Fields of `POST /api/v1/costmaps/{id}/routes`.
const CREATE_FIELDS: [&str; 7] = [
    "name",
    "start",
    "goal",
    "arc_cost",
    "epsilon",
    "smooth",
    "speed_m_s",
];
/// Fields of `POST /api/v1/routes/{id}/replan`.
const REPLAN_FIELDS: [&str; 4] = ["name", "position", "blocked", "cost_changes"];
/// Accepted ground speed, m/s: (0, SPEED_MAX].
const SPEED_MAX: f64 = 50.0;
/// Accepted cost of a cost change: (0, COST_MAX].
const COST_MAX: f64 = 1e6;
const POSITION_FORMS: &str =
    "[lon, lat] (WGS84 degrees) or {\"utm\": [easting, northing]} (metres in the route's UTM zone)";

fn unknown_fields(
    obj: &Map<String, Value>,
    allowed: &[&str],
    expected: &str,
    issues: &mut Vec<Issue>,
) {
    for key in obj.keys().filter(|k| !allowed.contains(&k.as_str())) {
        issues.push(Issue::new(
            &format!("/{}", escape_pointer_token(key)),
            &format!("unknown field {key:?}: expected {expected}"),
        ));
    }
}

fn parse_name(obj: &Map<String, Value>, issues: &mut Vec<Issue>) -> Option<String> {
    read_name(obj.get("name")).unwrap_or_else(|issue| {
        issues.push(issue);
        None
    })
}

/// An optional number; a fault when it is there but not a number.
fn parse_number(obj: &Map<String, Value>, key: &str, issues: &mut Vec<Issue>) -> Option<f64> {
    match obj.get(key) {
        None | Some(Value::Null) => None,
        Some(v) => v.as_f64().or_else(|| {
            issues.push(Issue::new(
                &format!("/{key}"),
                &format!("{key} must be a number"),
            ));
            None
        }),
    }
}

/// Two numbers.
fn pair(v: &Value) -> Option<[f64; 2]> {
    match v.as_array()?.as_slice() {
        [a, b] => Some([a.as_f64()?, b.as_f64()?]),
        _ => None,
    }
}

fn parse_position(
    value: Option<&Value>,
    pointer: &str,
    issues: &mut Vec<Issue>,
) -> Option<Position> {
    let mut fault = |p: &str, m: &str| {
        issues.push(Issue::new(p, m));
        None
    };
    match value {
        None | Some(Value::Null) => fault(pointer, &format!("required: {POSITION_FORMS}")),
        Some(v @ Value::Array(_)) => match pair(v) {
            Some([lon, lat])
                if (-180.0..=180.0).contains(&lon) && (-90.0..=90.0).contains(&lat) =>
            {
                Some(Position::LonLat([lon, lat]))
            }
            Some([lon, lat]) => fault(
                pointer,
                &format!(
                    "[{}, {}] is not a WGS84 position: lon must be in [-180, 180] and lat in \
                     [-90, 90] degrees",
                    planner_core::num::readable(lon),
                    planner_core::num::readable(lat)
                ),
            ),
            None => fault(pointer, &format!("must be {POSITION_FORMS}: two numbers")),
        },
        Some(Value::Object(o)) => {
            if let Some(key) = o.keys().find(|k| *k != "utm") {
                return fault(
                    &format!("{pointer}/{}", escape_pointer_token(key)),
                    &format!(
                        "unknown field {key:?}: a UTM position is {{\"utm\": [easting, northing]}}"
                    ),
                );
            }
            match o.get("utm").map(pair) {
                Some(Some(en)) => Some(Position::Utm { utm: en }),
                Some(None) => fault(
                    &format!("{pointer}/utm"),
                    "must be [easting, northing]: two numbers of metres",
                ),
                None => fault(pointer, &format!("must be {POSITION_FORMS}")),
            }
        }
        Some(_) => fault(pointer, &format!("must be {POSITION_FORMS}")),
    }
}

/// A checked `POST /api/v1/costmaps/{id}/routes` body.
pub(super) struct CreateRequest {
    pub(super) name: Option<String>,
    pub(super) start: Position,
    pub(super) goal: Position,
    pub(super) options: SearchOptions,
    pub(super) speed_m_s: Option<f64>,
}

pub(super) fn parse_create(doc: &Value) -> Result<CreateRequest, ApiError> {
    let Some(obj) = doc.as_object() else {
        return Err(ApiError::Validation(vec![Issue::new(
            "",
            "the request body must be a JSON object with start and goal (and optionally \
             arc_cost, epsilon, smooth, speed_m_s, name)",
        )]));
    };
    let mut issues = Vec::new();
    unknown_fields(
        obj,
        &CREATE_FIELDS,
        "start, goal, arc_cost, epsilon, smooth, speed_m_s or name",
        &mut issues,
    );
    let name = parse_name(obj, &mut issues);
    let start = parse_position(obj.get("start"), "/start", &mut issues);
    let goal = parse_position(obj.get("goal"), "/goal", &mut issues);
    let arc_cost = match obj.get("arc_cost") {
        None | Some(Value::Null) => ArcCost::default(),
        Some(v) => deserialize_at::<ArcCost>(v, "/arc_cost").unwrap_or_else(|i| {
            issues.push(i);
            ArcCost::default()
        }),
    };
    let epsilon = parse_number(obj, "epsilon", &mut issues).unwrap_or(1.0);
    let smooth = match obj.get("smooth") {
        None | Some(Value::Null) => true,
        Some(Value::Bool(b)) => *b,
        Some(_) => {
            issues.push(Issue::new("/smooth", "smooth must be true or false"));
            true
        }
    };
    let speed_m_s = parse_number(obj, "speed_m_s", &mut issues);
    if let Some(v) = speed_m_s
        && !(v > 0.0 && v <= SPEED_MAX)
    {
        issues.push(Issue::new(
            "/speed_m_s",
            &format!(
                "speed_m_s must be in (0, {SPEED_MAX}] m/s, got {}",
                planner_core::num::readable(v)
            ),
        ));
    }
    let options = SearchOptions {
        arc_cost,
        epsilon,
        smooth,
    };
    issues.extend(options.route_options(1).issues());
    match (start, goal) {
        (Some(start), Some(goal)) if issues.is_empty() => Ok(CreateRequest {
            name,
            start,
            goal,
            options,
            speed_m_s,
        }),
        _ => Err(ApiError::Validation(issues)),
    }
}

/// One polygon of a request, with the pointer of the member it came from.
pub(super) struct Area {
    pub(super) polygon: Polygon<f64>,
    pub(super) pointer: String,
}

/// The polygons of one GeoJSON area member, checked (shape, ranges,
/// self-intersection). Their vertices are added to `vertices`; once that
/// is over `max_vertices` they are no longer checked (the caller refuses
/// the request for the count).
fn parse_area(
    value: &Value,
    pointer: &str,
    issues: &mut Vec<Issue>,
    vertices: &mut usize,
    max_vertices: usize,
) -> Vec<Area> {
    match parse_polygons(value, pointer) {
        Ok(parsed) => {
            let mut out = Vec::new();
            for p in parsed {
                *vertices = vertices.saturating_add(p.polygon.coords_count());
                if *vertices > max_vertices {
                    continue;
                }
                let faults = polygon_issues(&p.polygon, &p.pointer);
                if faults.is_empty() {
                    out.push(Area {
                        polygon: p.polygon,
                        pointer: pointer.to_string(),
                    });
                } else {
                    issues.extend(faults);
                }
            }
            out
        }
        Err(faults) => {
            issues.extend(faults);
            Vec::new()
        }
    }
}

/// A checked `POST /api/v1/routes/{id}/replan` body.
pub(super) struct ReplanRequest {
    pub(super) name: Option<String>,
    pub(super) position: Position,
    pub(super) blocked: Vec<Area>,
    /// In order, each polygon with its cost.
    pub(super) cost_changes: Vec<(Area, f64)>,
}

/// The areas and vertices of the changes a chain of replans made so far.
#[derive(Clone, Copy, Default)]
pub(super) struct Earlier {
    areas: usize,
    vertices: usize,
}

impl Earlier {
    /// The counts of a chain's stored changes.
    pub(super) fn of(changes: &Changes) -> Result<Earlier, ApiError> {
        let mut earlier = Earlier {
            areas: changes.blocked.len() + changes.cost_changes.len(),
            vertices: 0,
        };
        for v in changes
            .blocked
            .iter()
            .chain(changes.cost_changes.iter().map(|c| &c.area))
        {
            earlier.vertices += stored_polygon(v)?.coords_count();
        }
        Ok(earlier)
    }
}

/// The vertices read so far against their limit.
struct VertexCount {
    vertices: usize,
    max_vertices: usize,
}

/// A replan body, its areas counted against `limits` (with the chain's
/// `earlier` changes) before any of them is checked.
pub(super) fn parse_replan(
    doc: &Value,
    limits: &Limits,
    earlier: Earlier,
) -> Result<ReplanRequest, ApiError> {
    let Some(obj) = doc.as_object() else {
        return Err(ApiError::Validation(vec![Issue::new(
            "",
            "the request body must be a JSON object with position (and optionally blocked, \
             cost_changes, name)",
        )]));
    };
    let mut issues = Vec::new();
    unknown_fields(
        obj,
        &REPLAN_FIELDS,
        "position, blocked, cost_changes or name",
        &mut issues,
    );
    let name = parse_name(obj, &mut issues);
    let position = parse_position(obj.get("position"), "/position", &mut issues);
    // The limits on geometry hold for the changes of a whole chain, and
    // apply before any area is read.
    let count = |key: &str| obj.get(key).and_then(Value::as_array).map_or(0, Vec::len);
    let (new_blocked, new_changes) = (count("blocked"), count("cost_changes"));
    let pointer = if new_blocked == 0 {
        "/cost_changes"
    } else {
        "/blocked"
    };
    let areas = earlier.areas + new_blocked + new_changes;
    if areas > limits.max_no_fly_zones {
        return Err(ApiError::Validation(vec![Issue::new(
            pointer,
            &format!(
                "{areas} areas (blocked and cost changes, with those of the earlier replans) \
                 exceed the limit of {}",
                limits.max_no_fly_zones
            ),
        )]));
    }
    let mut count = VertexCount {
        vertices: earlier.vertices,
        max_vertices: limits.max_vertices,
    };
    let blocked = parse_blocked(obj.get("blocked"), &mut issues, &mut count);
    let cost_changes = parse_cost_changes(obj.get("cost_changes"), &mut issues, &mut count);
    let VertexCount {
        vertices,
        max_vertices,
    } = count;
    if vertices > max_vertices {
        return Err(ApiError::Validation(vec![Issue::new(
            pointer,
            &format!(
                "{vertices} vertices in the areas (with those of the earlier replans) exceed the \
                 limit of {max_vertices}"
            ),
        )]));
    }
    match position {
        Some(position) if issues.is_empty() => Ok(ReplanRequest {
            name,
            position,
            blocked,
            cost_changes,
        }),
        _ => Err(ApiError::Validation(issues)),
    }
}

/// The `blocked` member: GeoJSON areas.
fn parse_blocked(
    value: Option<&Value>,
    issues: &mut Vec<Issue>,
    count: &mut VertexCount,
) -> Vec<Area> {
    let mut blocked = Vec::new();
    match value {
        None | Some(Value::Null) => {}
        Some(Value::Array(areas)) => {
            for (i, v) in areas.iter().enumerate() {
                if issues.len() > MAX_ISSUES {
                    break;
                }
                blocked.extend(parse_area(
                    v,
                    &format!("/blocked/{i}"),
                    issues,
                    &mut count.vertices,
                    count.max_vertices,
                ));
            }
        }
        Some(_) => issues.push(Issue::new(
            "/blocked",
            "must be an array of GeoJSON Polygons (or Features of them)",
        )),
    }
    blocked
}

/// The `cost_changes` member: `{"area", "cost"}` objects, each area's
/// polygons with the cost, in order.
fn parse_cost_changes(
    value: Option<&Value>,
    issues: &mut Vec<Issue>,
    count: &mut VertexCount,
) -> Vec<(Area, f64)> {
    let mut cost_changes = Vec::new();
    match value {
        None | Some(Value::Null) => {}
        Some(Value::Array(changes)) => {
            for (i, v) in changes.iter().enumerate() {
                if issues.len() > MAX_ISSUES {
                    break;
                }
                let pointer = format!("/cost_changes/{i}");
                let Some(change) = v.as_object() else {
                    issues.push(Issue::new(
                        &pointer,
                        "must be an object {\"area\": GeoJSON Polygon, \"cost\": number}",
                    ));
                    continue;
                };
                cost_changes.extend(parse_cost_change(change, &pointer, issues, count));
            }
        }
        Some(_) => issues.push(Issue::new(
            "/cost_changes",
            "must be an array of {\"area\": GeoJSON Polygon, \"cost\": number}",
        )),
    }
    cost_changes
}

/// One cost change at `pointer`: its area's polygons, each with the cost.
fn parse_cost_change(
    change: &Map<String, Value>,
    pointer: &str,
    issues: &mut Vec<Issue>,
    count: &mut VertexCount,
) -> Vec<(Area, f64)> {
    for key in change
        .keys()
        .filter(|k| !["area", "cost"].contains(&k.as_str()))
    {
        issues.push(Issue::new(
            &format!("{pointer}/{}", escape_pointer_token(key)),
            &format!("unknown field {key:?}: expected area or cost"),
        ));
    }
    let areas = match change.get("area") {
        None | Some(Value::Null) => {
            issues.push(Issue::new(
                &format!("{pointer}/area"),
                "required: a GeoJSON Polygon",
            ));
            Vec::new()
        }
        Some(a) => parse_area(
            a,
            &format!("{pointer}/area"),
            issues,
            &mut count.vertices,
            count.max_vertices,
        ),
    };
    let cost = match change.get("cost").and_then(Value::as_f64) {
        Some(c) if c > 0.0 && c <= COST_MAX => Some(c),
        Some(c) => {
            issues.push(Issue::new(
                &format!("{pointer}/cost"),
                &format!(
                    "the cost must be a number in (0, {COST_MAX}], got {} (block \
                     an area with `blocked`)",
                    planner_core::num::readable(c)
                ),
            ));
            None
        }
        None => {
            issues.push(Issue::new(
                &format!("{pointer}/cost"),
                &format!("required: a number in (0, {COST_MAX}]"),
            ));
            None
        }
    };
    match cost {
        Some(cost) => areas.into_iter().map(|a| (a, cost)).collect(),
        None => Vec::new(),
    }
}

/// A polygon as GeoJSON, CCW exterior and CW holes (SPEC §2).
pub(super) fn polygon_geojson(p: &Polygon<f64>) -> Value {
    let p = p.orient(Direction::Default);
    let ring =
        |r: &LineString<f64>| -> Vec<Value> { r.0.iter().map(|c| json!([c.x, c.y])).collect() };
    let mut rings = vec![ring(p.exterior())];
    rings.extend(p.interiors().iter().map(ring));
    json!({"type": "Polygon", "coordinates": rings})
}

/// A stored polygon read back.
pub(super) fn stored_polygon(v: &Value) -> Result<Polygon<f64>, ApiError> {
    match parse_polygons(v, "").as_deref() {
        Ok([p]) => Ok(p.polygon.clone()),
        _ => Err(ApiError::Internal(format!(
            "a stored area is not one polygon: {v}"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::super::model::Planner;
    use super::*;

    fn pointers<T>(r: Result<T, ApiError>) -> Vec<String> {
        match r {
            Err(ApiError::Validation(issues)) => issues.into_iter().map(|i| i.pointer).collect(),
            Err(e) => panic!("expected issues, got {e}"),
            Ok(_) => panic!("expected issues"),
        }
    }

    #[test]
    fn create_requests() {
        let r = parse_create(&json!({"start": [-75.0, 38.8], "goal": {"utm": [500000, 4300000]}}))
            .unwrap();
        assert_eq!(r.start, Position::LonLat([-75.0, 38.8]));
        assert_eq!(
            r.goal,
            Position::Utm {
                utm: [500_000.0, 4_300_000.0]
            }
        );
        assert_eq!(r.options.arc_cost, ArcCost::Integrated);
        assert_eq!(r.options.planner(), Planner::DstarLite);
        assert!(r.options.smooth);
        let r = parse_create(&json!({
            "start": [0, 0], "goal": [1, 1], "epsilon": 2, "arc_cost": {"mode": "thesis"},
            "smooth": false, "speed_m_s": 1.5, "name": "r"
        }))
        .unwrap();
        assert_eq!(r.options.planner(), Planner::Astar);
        assert_eq!(r.options.arc_cost, ArcCost::thesis());
        assert_eq!(r.speed_m_s, Some(1.5));
        assert_eq!(r.options.route_options(10).max_expansions, Some(40));
    }

    #[test]
    fn create_faults_are_named_by_pointer() {
        let p = pointers(parse_create(&json!({
            "start": [200, 0],
            "goal": {"utm": [1]},
            "epsilon": 0.5,
            "arc_cost": {"mode": "thesis", "d_max": 0},
            "smooth": 1,
            "speed_m_s": 0,
            "colour": "red",
        })));
        assert_eq!(
            p,
            [
                "/colour",
                "/start",
                "/goal/utm",
                "/smooth",
                "/speed_m_s",
                "/epsilon",
                "/arc_cost/d_max"
            ]
        );
        assert_eq!(pointers(parse_create(&json!({}))), ["/start", "/goal"]);
        assert_eq!(
            pointers(parse_create(
                &json!({"start": [0, 0], "goal": {"utm": [1, 2], "zone": 3}})
            )),
            ["/goal/zone"]
        );
        assert_eq!(
            pointers(parse_create(
                &json!({"start": [0, 0], "goal": [0, 0], "arc_cost": {"mode": "mcp"}})
            )),
            ["/arc_cost/mode"]
        );
        assert_eq!(pointers(parse_create(&json!([1]))), [""]);
    }

    fn square(x: f64, y: f64, d: f64) -> Value {
        json!({"type": "Polygon", "coordinates": [[[x, y], [x + d, y], [x + d, y + d], [x, y + d], [x, y]]]})
    }

    fn replan_of(doc: &Value) -> Result<ReplanRequest, ApiError> {
        parse_replan(doc, &Limits::default(), Earlier::default())
    }

    #[test]
    fn replan_limits_apply_before_any_area_is_checked() {
        let limits = Limits {
            max_no_fly_zones: 3,
            max_vertices: 12,
            ..Limits::default()
        };
        let bowtie =
            json!({"type": "Polygon", "coordinates": [[[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]]]});
        let detail = |r: Result<ReplanRequest, ApiError>| match r {
            Err(ApiError::Validation(issues)) => issues
                .iter()
                .map(|i| format!("{}: {}", i.pointer, i.message))
                .collect::<Vec<_>>(),
            Err(e) => panic!("{e}"),
            Ok(_) => panic!("accepted"),
        };
        // Four areas, one of them with the earlier replans: one fault, the
        // count, and the bow tie is not looked at.
        let four = json!({"position": [0, 0], "blocked": [bowtie, square(0.0, 0.0, 1.0)], "cost_changes": [{"area": square(2.0, 0.0, 1.0), "cost": 2}]});
        let one = Earlier {
            areas: 1,
            vertices: 0,
        };
        assert_eq!(
            detail(parse_replan(&four, &limits, one)),
            [
                "/blocked: 4 areas (blocked and cost changes, with those of the earlier replans) exceed the limit of 3"
            ]
        );
        assert!(parse_replan(&four, &limits, Earlier::default()).is_err());
        // Vertices: 5 + 5 + 5 over 12 (3 earlier ones make it 18).
        let three = json!({"position": [0, 0], "blocked": [square(0.0, 0.0, 1.0), bowtie, square(2.0, 0.0, 1.0)]});
        let earlier = Earlier {
            areas: 0,
            vertices: 3,
        };
        assert_eq!(
            detail(parse_replan(&three, &limits, earlier)),
            [
                "/blocked: 18 vertices in the areas (with those of the earlier replans) exceed the limit of 12"
            ]
        );
        // Under both: the bow tie's fault, by pointer.
        let two = json!({"position": [0, 0], "cost_changes": [{"area": bowtie, "cost": 2}]});
        let faults = detail(parse_replan(&two, &limits, earlier));
        assert_eq!(faults.len(), 1, "{faults:?}");
        assert!(faults[0].starts_with("/cost_changes/0/area"), "{faults:?}");
    }

    #[test]
    fn replan_requests_and_faults() {
        let r = replan_of(&json!({
            "position": [0, 0],
            "blocked": [square(0.0, 0.0, 1.0), {"type": "Feature", "properties": {}, "geometry": square(2.0, 0.0, 1.0)}],
            "cost_changes": [{"area": square(5.0, 5.0, 1.0), "cost": 7}],
        }))
        .unwrap();
        assert_eq!(r.blocked.len(), 2);
        assert_eq!(r.blocked[1].pointer, "/blocked/1");
        assert_eq!(r.cost_changes.len(), 1);
        assert_eq!(r.cost_changes[0].1, 7.0);
        let bowtie =
            json!({"type": "Polygon", "coordinates": [[[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]]]});
        let p = pointers(replan_of(&json!({
            "blocked": [square(0.0, 0.0, 1.0), bowtie],
            "cost_changes": [{"area": square(0.0, 0.0, 1.0), "cost": 0}, {"cost": 2}, {"area": {"type": "Point", "coordinates": [0, 0]}, "cost": f64::MAX, "x": 1}],
            "extra": true,
        })));
        assert_eq!(p[0], "/extra");
        assert_eq!(p[1], "/position");
        assert!(p[2].starts_with("/blocked/1"), "{p:?}");
        let rest = &p[3..];
        for expected in [
            "/cost_changes/0/cost",
            "/cost_changes/1/area",
            "/cost_changes/2/x",
            "/cost_changes/2/area/type",
            "/cost_changes/2/cost",
        ] {
            assert!(
                rest.contains(&expected.to_string()),
                "{expected} not in {p:?}"
            );
        }
    }

    #[test]
    fn stored_polygons_round_trip_counter_clockwise() {
        // Given clockwise, stored counter-clockwise and closed.
        let cw = json!({"type": "Polygon", "coordinates": [[[0, 0], [0, 1], [1, 1], [1, 0]]]});
        let mut issues = Vec::new();
        let areas = parse_area(&cw, "/blocked/0", &mut issues, &mut 0, usize::MAX);
        assert!(issues.is_empty());
        let v = polygon_geojson(&areas[0].polygon);
        assert_eq!(
            v["coordinates"][0],
            json!([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]])
        );
        assert_eq!(
            stored_polygon(&v).unwrap(),
            areas[0].polygon.orient(Direction::Default)
        );
    }
}
