//! The DJI files of a plan, per multirotor sortie: a WPML mission
//! (`<stem>.kmz`, for the aircraft `dji_aircraft` names) and a Litchi
//! mission (`<stem>.litchi.csv`, or `<stem>.part<k>.litchi.csv`, k from 1,
//! past 99 waypoints); and the warnings for sorties DJI cannot fly.

use super::files::PlanFile;
use super::request::SurveyParams;
use super::result::{SortiePlan, SurveyPlan, UavPlan};
use crate::export::litchi::LitchiMission;
use crate::export::wpml::{WpmlOptions, check_wpml, write_kmz};
use crate::export::wpml_route::is_multirotor;
use crate::export::{AltitudeFrame, wpml};
use crate::geo::Issue;

/// Suffix of a sortie's DJI WPML mission, after `<stem>.`.
pub(super) const KMZ_SUFFIX: &str = "kmz";
/// Suffix of a sortie's Litchi missions, after `<stem>.` or `<stem>.part<k>.`.
pub(super) const LITCHI_SUFFIX: &str = "litchi.csv";
/// Lowest return height DJI accepts, m (`wpml:globalRTHHeight`).
const MIN_RTH_HEIGHT_M: f64 = 2.0;

/// `plan.json` names the DJI aircraft only when it is not the default.
pub(super) fn is_default_dji(a: &wpml::DjiAircraft) -> bool {
    *a == wpml::DjiAircraft::default()
}

impl SurveyParams {
    /// `dji_aircraft` against the altitude frame: terrain following is a
    /// Mavic 3 enterprise's only.
    pub(super) fn check_dji(&self, issues: &mut Vec<Issue>, p: &dyn Fn(&str) -> String) {
        if self.altitude_frame == AltitudeFrame::Terrain && !self.dji_aircraft.follows_terrain() {
            issues.push(Issue::new(
                &p("dji_aircraft"),
                &wpml::WpmlError::NoTerrainFollow(self.dji_aircraft).to_string(),
            ));
        }
    }
}

impl SurveyPlan {
    /// The WPML options of `uav`: the survey's aircraft, returning home
    /// at the highest altitude the UAV flies (where its rally points are).
    fn wpml_options(&self, uav: &UavPlan) -> WpmlOptions {
        WpmlOptions {
            aircraft: self.dji_aircraft,
            rth_height_m: self.return_height_m(uav).max(MIN_RTH_HEIGHT_M),
        }
    }

    /// The multirotor sorties, with their UAV.
    fn dji_sorties(&self) -> impl Iterator<Item = (&UavPlan, &SortiePlan)> {
        self.uavs.iter().flat_map(|u| {
            u.sorties
                .iter()
                .filter(|s| is_multirotor(&s.mission))
                .map(move |s| (u, s))
        })
    }

    /// The DJI files of sortie `s` of `uav`, after `<stem>.`: `kmz` when
    /// DJI can fly it as a WPML mission, and its Litchi file(s)
    /// (`litchi.csv`, or `part1.litchi.csv`, … past 99 waypoints); none
    /// for a plane's or a VTOL's.
    pub fn dji_suffixes(&self, uav: &UavPlan, s: &SortiePlan) -> Vec<String> {
        let mut out = Vec::new();
        if !is_multirotor(&s.mission) {
            return out;
        }
        if check_wpml(&s.mission, &self.wpml_options(uav)).is_ok() {
            out.push(KMZ_SUFFIX.to_string());
        }
        match LitchiMission::of(&s.mission).map(|l| l.parts()) {
            Ok(1) => out.push(LITCHI_SUFFIX.to_string()),
            Ok(n) => out.extend((1..=n).map(|k| format!("part{k}.{LITCHI_SUFFIX}"))),
            Err(_) => {}
        }
        out
    }

    /// Names of the DJI files: per multirotor sortie DJI can fly, its
    /// `.kmz` and its Litchi file(s).
    pub(super) fn dji_file_names(&self) -> Vec<String> {
        self.dji_sorties()
            .flat_map(|(u, s)| {
                self.dji_suffixes(u, s)
                    .into_iter()
                    .map(|x| format!("{}.{x}", s.file_stem))
            })
            .collect()
    }

    /// The DJI file `name` names, rendered; `None` for another name.
    pub(super) fn dji_file(&self, name: &str) -> Option<PlanFile> {
        if let Some(stem) = name
            .strip_suffix(KMZ_SUFFIX)
            .and_then(|n| n.strip_suffix('.'))
        {
            let (u, s) = self.dji_sorties().find(|(_, s)| s.file_stem == stem)?;
            return Some(PlanFile {
                name: name.to_string(),
                content_type: super::files::content_type_of(name),
                content: write_kmz(&s.mission, &self.wpml_options(u)).ok()?,
            });
        }
        let stem = name.strip_suffix(LITCHI_SUFFIX)?.strip_suffix('.')?;
        // `<stem>` for a mission in one file, `<stem>.part<k>` beyond.
        // (Written back, the same name: `part01` is no part.)
        let (stem, part) = match stem.rsplit_once(".part") {
            Some((s, k)) => match k.parse::<usize>() {
                Ok(k) if k >= 1 && format!("{s}.part{k}.{LITCHI_SUFFIX}") == name => (s, Some(k)),
                _ => (stem, None),
            },
            None => (stem, None),
        };
        let (_, s) = self.dji_sorties().find(|(_, s)| s.file_stem == stem)?;
        let litchi = LitchiMission::of(&s.mission).ok()?;
        let k = match (part, litchi.parts()) {
            (None, 1) => 0,
            (Some(k), n) if n > 1 => k - 1,
            _ => return None,
        };
        Some(PlanFile {
            name: name.to_string(),
            content_type: super::files::content_type_of(name),
            content: litchi.csv(k).ok()?.into_bytes(),
        })
    }

    /// Every Litchi file of every multirotor sortie, each sortie's parts
    /// from one conversion of its mission (a long survey has hundreds of
    /// parts: converting it again for each made the files cost more than
    /// the plan).
    pub(super) fn litchi_files(&self) -> Vec<Vec<PlanFile>> {
        self.dji_sorties()
            .filter_map(|(_, s)| {
                let litchi = LitchiMission::of(&s.mission).ok()?;
                let n = litchi.parts();
                let files = (0..n)
                    .filter_map(|k| {
                        let name = if n == 1 {
                            format!("{}.{LITCHI_SUFFIX}", s.file_stem)
                        } else {
                            format!("{}.part{}.{LITCHI_SUFFIX}", s.file_stem, k + 1)
                        };
                        Some(PlanFile {
                            content_type: super::files::content_type_of(&name),
                            content: litchi.csv(k).ok()?.into_bytes(),
                            name,
                        })
                    })
                    .collect();
                Some(files)
            })
            .collect()
    }

    /// Whether `name` is a Litchi file's (of [`SurveyPlan::litchi_files`]).
    pub(super) fn is_litchi_file(name: &str) -> bool {
        name.ends_with(&format!(".{LITCHI_SUFFIX}"))
    }

    /// Why a multirotor sortie gets no DJI WPML or Litchi mission.
    pub(super) fn dji_warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        for (u, s) in self.dji_sorties() {
            if let Err(e) = check_wpml(&s.mission, &self.wpml_options(u)) {
                out.push(format!(
                    "{}: no DJI WPML mission ({}.{KMZ_SUFFIX}): {e}",
                    s.file_stem, s.file_stem
                ));
            }
            if let Err(e) = LitchiMission::of(&s.mission) {
                out.push(format!(
                    "{}: no Litchi mission ({}.{LITCHI_SUFFIX}): {e}",
                    s.file_stem, s.file_stem
                ));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::super::{SurveyRequest, plan_survey};
    use crate::export::wpml::DjiAircraft;
    use crate::geo::Limits;
    use serde_json::{Value, json};

    fn plan(extra: Value) -> Result<super::SurveyPlan, super::super::PlanError> {
        let mut doc = json!({
            "roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.004, 52.0], [5.004, 52.003], [5.0, 52.003]]]},
            "slice_angle_deg": 0,
            "uavs": [{"id": "a", "start": [4.999, 51.999]}],
        });
        for (k, v) in extra.as_object().unwrap() {
            doc[k] = v.clone();
        }
        plan_survey(&SurveyRequest::from_document(&doc)?, &Limits::default())
    }

    #[test]
    fn a_multirotor_sortie_gets_a_kmz_and_a_litchi_file() {
        let p = plan(json!({"dji_aircraft": "m30t"})).unwrap();
        assert_eq!(p.dji_aircraft, DjiAircraft::M30t);
        let names = p.file_names();
        assert!(names.contains(&"a.kmz".to_string()), "{names:?}");
        assert!(names.contains(&"a.litchi.csv".to_string()), "{names:?}");
        let kmz = p.file("a.kmz").unwrap();
        assert_eq!(kmz.content_type, "application/vnd.google-earth.kmz");
        // A zip: its local file header signature.
        assert_eq!(&kmz.content[..4], b"PK\x03\x04");
        let csv = p.file("a.litchi.csv").unwrap();
        assert_eq!(csv.content_type, "text/csv; charset=utf-8");
        assert!(csv.text().starts_with("latitude,longitude,altitude(m),"));
        // As many rows as the mission has waypoints.
        let wpl = p.file("a.waypoints").unwrap();
        let waypoints = wpl
            .text()
            .lines()
            .filter(|l| l.split('\t').nth(3) == Some("16"))
            .count();
        assert_eq!(
            csv.text().lines().count(),
            1 + waypoints - 1,
            "home is row 16 too"
        );
        assert!(p.file("a.part1.litchi.csv").is_none());
        assert!(p.file("b.kmz").is_none());
        assert!(p.dji_warnings().is_empty());
    }

    #[test]
    fn terrain_following_with_an_aircraft_that_cannot_is_refused() {
        let e = plan(json!({"dji_aircraft": "m350_h20", "altitude_frame": "terrain"})).unwrap_err();
        let super::super::PlanError::Invalid(issues) = e else {
            panic!("{e:?}")
        };
        assert_eq!(issues[0].pointer, "/dji_aircraft");
        assert!(
            issues[0]
                .message
                .contains("m350_h20 cannot follow the terrain")
        );
        let e = plan(json!({"dji_aircraft": "m2"})).unwrap_err();
        assert!(format!("{e:?}").contains("dji_aircraft"), "{e:?}");
    }

    #[test]
    fn too_fast_for_dji_gives_a_warning_and_no_dji_files() {
        let p = plan(json!({"speed_m_s": 18})).unwrap();
        let names = p.file_names();
        assert!(
            !names
                .iter()
                .any(|n| n.ends_with(".kmz") || n.ends_with(".csv"))
        );
        assert!(
            p.warnings
                .iter()
                .any(|w| w.contains("a: no DJI WPML mission (a.kmz)") && w.contains("1-15 m/s")),
            "{:?}",
            p.warnings
        );
    }
}
