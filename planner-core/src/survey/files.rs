//! The files of a plan: their names, and each rendered alone (mission
//! files per sortie, the fence per UAV, the cells), for the CLI's output
//! directory and the service's downloads.

use rayon::prelude::*;
use serde::ser::{Serialize, SerializeMap, Serializer};
use serde_json::{Map, Value, json};

use super::result::{CellOut, SurveyPlan};
use crate::export;

/// A file produced from a plan.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanFile {
    pub name: String,
    pub content_type: &'static str,
    /// Bytes: text files are UTF-8, a DJI mission (`.kmz`) is a zip.
    pub content: Vec<u8>,
}

impl PlanFile {
    /// The content as text (empty for a binary file such as a `.kmz`).
    pub fn text(&self) -> &str {
        std::str::from_utf8(&self.content).unwrap_or_default()
    }
}

impl SurveyPlan {
    /// Names of the plan's files: per sortie `<stem>.waypoints`,
    /// `<stem>.plan`, `<stem>.route.geojson` and `<stem>.kml` (the stem is
    /// the UAV id, or `<id>.sortie<k>` for a UAV flying several sorties);
    /// per UAV `<id>.fence.waypoints`; `<id>.photos.geojson` per UAV whose
    /// photos were planned; the rally files; the DJI files of each
    /// multirotor sortie (`.kmz`, `.litchi.csv`); then `cells.geojson`.
    pub fn file_names(&self) -> Vec<String> {
        let mut out: Vec<String> = Vec::new();
        for u in &self.uavs {
            for s in &u.sorties {
                out.extend(
                    SORTIE_FILE_SUFFIXES
                        .iter()
                        .map(|suffix| format!("{}.{suffix}", s.file_stem)),
                );
            }
            out.push(format!("{}.{FENCE_FILE_SUFFIX}", u.id));
        }
        out.extend(self.photo_file_names());
        out.extend(self.rally_file_names());
        out.extend(self.dji_file_names());
        out.push(CELLS_FILE.to_string());
        out
    }

    /// Every file of the plan, rendered (each alone, so side by side).
    pub fn files(&self) -> Vec<PlanFile> {
        self.file_names()
            .par_iter()
            .filter_map(|n| self.file(n))
            .collect()
    }

    /// Renders every file of the plan side by side and hands each to
    /// `take` as soon as it is made (so a caller writing them to disk
    /// overlaps the writing with the rendering and holds few in memory);
    /// stops at the first error `take` returns.
    pub fn each_file<E: Send>(
        &self,
        take: impl Fn(PlanFile) -> Result<(), E> + Sync,
    ) -> Result<(), E> {
        let names: Vec<String> = self
            .file_names()
            .into_iter()
            .filter(|n| !SurveyPlan::is_litchi_file(n))
            .collect();
        // Side by side: the Litchi parts need no other file, and one long
        // file (a big `.kmz`) would otherwise leave a core idle.
        let (files, litchi) = rayon::join(
            || {
                names
                    .par_iter()
                    .filter_map(|n| self.file(n))
                    .try_for_each(&take)
            },
            || {
                self.litchi_files()
                    .into_par_iter()
                    .flatten()
                    .try_for_each(&take)
            },
        );
        files.and(litchi)
    }

    /// One file of the plan by name (see [`SurveyPlan::file_names`]),
    /// rendered alone; `None` for an unknown name.
    pub fn file(&self, name: &str) -> Option<PlanFile> {
        let done = |content: String| {
            Some(PlanFile {
                name: name.to_string(),
                content_type: content_type_of(name),
                content: content.into_bytes(),
            })
        };
        if name == CELLS_FILE {
            return done(pretty(&CellsDocument(self)));
        }
        if let Some(rally) = self.rally_file(name) {
            return Some(rally);
        }
        if let Some(photos) = self.photos_file(name) {
            return Some(photos);
        }
        if let Some(dji) = self.dji_file(name) {
            return Some(dji);
        }
        // The fence is the UAV's; it is also served under each sortie's stem.
        let fence = format!(".{FENCE_FILE_SUFFIX}");
        if self.uavs.iter().any(|u| {
            std::iter::once(u.id.as_str())
                .chain(u.sorties.iter().map(|s| s.file_stem.as_str()))
                .any(|stem| name.strip_prefix(stem) == Some(fence.as_str()))
        }) {
            return done(export::write_fence(&self.fences));
        }
        let (u, s, suffix) = self.uavs.iter().find_map(|u| {
            u.sorties.iter().find_map(|s| {
                let rest = name.strip_prefix(s.file_stem.as_str())?.strip_prefix('.')?;
                SORTIE_FILE_SUFFIXES.contains(&rest).then_some((u, s, rest))
            })
        })?;
        match suffix {
            "waypoints" => done(export::write_waypoints(&s.mission)),
            "plan" => done(export::write_plan(
                &s.mission,
                &self.fences,
                &self.rally_for(u),
            )),
            "route.geojson" => {
                let mut props = Map::new();
                props.insert("uav".into(), json!(u.id));
                props.insert("sortie".into(), json!(s.file_stem));
                props.insert("altitude_frame".into(), json!(self.altitude_frame));
                props.insert("length_m".into(), json!(s.stats.length_m));
                props.insert("flight_time_s".into(), json!(s.stats.flight_time_s));
                let route =
                    json!({"type": "FeatureCollection", "features": [s.route_feature(props)]});
                done(pretty(&route))
            }
            "kml" => {
                // A set: a sortie may fly thousands of cells.
                let flown: std::collections::HashSet<usize> = s.cells.iter().copied().collect();
                let cell_rings: Vec<(String, Vec<[f64; 2]>)> = self
                    .cells
                    .iter()
                    .filter(|c| flown.contains(&c.id))
                    .map(|c| (format!("cell {}", c.id), geojson_exterior(&c.polygon)))
                    .collect();
                let title = if u.sorties.len() > 1 {
                    format!("terraplan survey, UAV {}, {}", u.id, s.file_stem)
                } else {
                    format!("terraplan survey, UAV {}", u.id)
                };
                done(export::write_kml(&title, &s.mission, &cell_rings))
            }
            _ => None,
        }
    }

    /// The cells as a GeoJSON FeatureCollection (WGS84).
    pub fn cells_geojson(&self) -> Value {
        serde_json::to_value(CellsDocument(self)).unwrap_or_default()
    }
}

/// The cells' FeatureCollection, serialised from the plan's cells without
/// copying their polygons (the file is tens of MB among thousands of
/// no-fly zones). Keys in byte order, as a JSON object map sorts them.
struct CellsDocument<'a>(&'a SurveyPlan);

impl Serialize for CellsDocument<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(2))?;
        map.serialize_entry("features", &CellFeatures(&self.0.cells))?;
        map.serialize_entry("type", "FeatureCollection")?;
        map.end()
    }
}

struct CellFeatures<'a>(&'a [CellOut]);

impl Serialize for CellFeatures<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.0.iter().map(CellFeature))
    }
}

struct CellFeature<'a>(&'a CellOut);

impl Serialize for CellFeature<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let c = self.0;
        let mut props = Map::new();
        props.insert("id".into(), json!(c.id));
        props.insert("area_m2".into(), json!(c.area_m2));
        props.insert("lane_bearing_deg".into(), json!(c.lane_bearing_deg));
        props.insert("lanes".into(), json!(c.lanes));
        props.insert("lane_length_m".into(), json!(c.lane_length_m));
        if let Some(photos) = &c.photos {
            photos.add_properties(&mut props);
        }
        let mut map = s.serialize_map(Some(3))?;
        map.serialize_entry("geometry", &c.polygon)?;
        map.serialize_entry("properties", &props)?;
        map.serialize_entry("type", "Feature")?;
        map.end()
    }
}

/// The media type of a plan file, known from its name alone (so a listing
/// of the files needs none of them rendered).
pub fn content_type_of(name: &str) -> &'static str {
    if name.ends_with(".geojson") {
        "application/geo+json"
    } else if name.ends_with(".plan") {
        "application/json"
    } else if name.ends_with(".kml") {
        "application/vnd.google-earth.kml+xml"
    } else if name.ends_with(".kmz") {
        "application/vnd.google-earth.kmz"
    } else if name.ends_with(".csv") {
        "text/csv; charset=utf-8"
    } else {
        "text/plain; charset=utf-8"
    }
}

/// Suffixes of each sortie's files, after `<stem>.`.
const SORTIE_FILE_SUFFIXES: [&str; 4] = ["waypoints", "plan", "route.geojson", "kml"];
/// Suffix of each UAV's fence file, after `<uav id>.`.
const FENCE_FILE_SUFFIX: &str = "fence.waypoints";
/// Name of the cells file.
const CELLS_FILE: &str = "cells.geojson";

/// The exterior ring of a GeoJSON Polygon geometry as [lon, lat] pairs.
fn geojson_exterior(polygon: &Value) -> Vec<[f64; 2]> {
    polygon["coordinates"][0]
        .as_array()
        .map(|ring| {
            ring.iter()
                .filter_map(|p| Some([p[0].as_f64()?, p[1].as_f64()?]))
                .collect()
        })
        .unwrap_or_default()
}

/// `v` as indented JSON with a final newline.
fn pretty<T: Serialize + ?Sized>(v: &T) -> String {
    let mut s = serde_json::to_string_pretty(v).unwrap_or_default();
    s.push('\n');
    s
}

#[cfg(test)]
mod tests {
    use super::super::{SurveyRequest, plan_survey};
    use crate::geo::Limits;
    use serde_json::json;

    #[test]
    fn plans_a_square_and_renders_each_file_alone() {
        let doc = json!({
            "roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.004, 52.0], [5.004, 52.003], [5.0, 52.003]]]},
            "no_fly_zones": [{"type": "Polygon", "coordinates": [[[5.001, 52.001], [5.002, 52.001], [5.002, 52.002], [5.001, 52.002]]]}],
            "slice_angle_deg": 0,
            "uavs": [{"id": "a-1", "start": [4.999, 51.999]}],
        });
        let plan = plan_survey(
            &SurveyRequest::from_document(&doc).unwrap(),
            &Limits::default(),
        )
        .unwrap();
        // An NFZ inside a square sliced north-south: left, below, above, right.
        assert_eq!(plan.stats.cell_count, 4);
        assert!(
            plan.stats.coverage_ratio >= 0.995,
            "{}",
            plan.stats.coverage_ratio
        );
        let names = plan.file_names();
        assert_eq!(
            names,
            [
                "a-1.waypoints",
                "a-1.plan",
                "a-1.route.geojson",
                "a-1.kml",
                "a-1.fence.waypoints",
                "a-1.photos.geojson",
                "a-1.kmz",
                "a-1.litchi.csv",
                "cells.geojson"
            ]
        );
        let all = plan.files();
        assert_eq!(all.len(), names.len());
        for f in &all {
            assert_eq!(plan.file(&f.name).as_ref(), Some(f));
            // A listing made from the names alone says the same.
            assert_eq!(
                super::content_type_of(&f.name),
                f.content_type,
                "{}",
                f.name
            );
        }
        assert!(plan.file("a-1.exe").is_none());
        assert!(!plan.file_names().iter().any(|n| n.contains(".part")));
        assert!(plan.file("b.waypoints").is_none());
        assert!(
            plan.file("a-1.waypoints")
                .unwrap()
                .text()
                .starts_with("QGC WPL 110\n")
        );
    }

    /// A long mission's Litchi parts, rendered together by `each_file`,
    /// are the files `file` renders one by one.
    #[test]
    fn each_file_renders_every_file_once() {
        let doc = json!({
            "roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.01, 52.0], [5.01, 52.006], [5.0, 52.006]]]},
            "slice_angle_deg": 0,
            "line_spacing_m": 6,
            "uavs": [{"id": "a", "start": [4.999, 51.999]}],
        });
        let plan = plan_survey(
            &SurveyRequest::from_document(&doc).unwrap(),
            &Limits::default(),
        )
        .unwrap();
        let names = plan.file_names();
        assert!(
            names.contains(&"a.part2.litchi.csv".to_string()),
            "{names:?}"
        );
        let made = std::sync::Mutex::new(Vec::new());
        plan.each_file(|f| {
            made.lock().unwrap().push(f);
            Ok::<(), ()>(())
        })
        .unwrap();
        let mut made = made.into_inner().unwrap();
        made.sort_by(|a, b| a.name.cmp(&b.name));
        let mut all = plan.files();
        all.sort_by(|a, b| a.name.cmp(&b.name));
        assert_eq!(made.len(), names.len());
        assert!(made == all, "each_file and files differ");
    }
}
