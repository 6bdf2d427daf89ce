//! Ground vehicle profiles: the numbers a costmap is built for.
//!
//! A profile is a named preset with any of its numbers overridden, or a
//! custom profile written out in full (every field given).

use serde::{Deserialize, Serialize};

use crate::geo::Issue;

/// What the costmap needs to know about a ground vehicle.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Vehicle {
    /// The preset it started from, or `custom`.
    pub name: String,
    /// Highest step (wall, kerb, ledge) it climbs, metres (thesis max_h).
    pub max_step_m: f64,
    /// Steepest slope it drives, degrees (thesis max_slope).
    pub max_slope_deg: f64,
    /// Footprint across (track to track), metres.
    pub width_m: f64,
    /// Footprint along, metres.
    pub length_m: f64,
    /// Weight of the obstacle-proximity cost (thesis w_infl).
    pub w_infl: f64,
    /// Weight of the slope cost (thesis w_slope).
    pub w_slope: f64,
}

/// The named profiles.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum VehiclePreset {
    /// The thesis' U-Go tracked robot (§2.5, Table 3.1): 75 cm long, 88 cm
    /// wide, climbs 15 cm, drives 25° (80 % of the −29°…32° pitch it
    /// survived when driven to its limits).
    UGo,
    /// A small wheeled robot of the Clearpath Jackal class (508 × 430 mm,
    /// 20 cm wheels, 65 mm ground clearance): steps up to 5 cm, slopes up
    /// to 20°; wheels slip before tracks, so slope weighs 1.5× as much as
    /// for the U-Go.
    SmallWheeled,
    /// A large skid-steer of the Clearpath Warthog class (1.52 × 1.38 m,
    /// 0.6 m tyres, 0.25 m clearance): steps up to 25 cm, slopes up to 30°.
    LargeSkidSteer,
}

impl VehiclePreset {
    pub const ALL: [VehiclePreset; 3] = [
        VehiclePreset::UGo,
        VehiclePreset::SmallWheeled,
        VehiclePreset::LargeSkidSteer,
    ];

    pub fn name(self) -> &'static str {
        match self {
            VehiclePreset::UGo => "u-go",
            VehiclePreset::SmallWheeled => "small-wheeled",
            VehiclePreset::LargeSkidSteer => "large-skid-steer",
        }
    }

    pub fn vehicle(self) -> Vehicle {
        let (max_step_m, max_slope_deg, width_m, length_m, w_infl, w_slope) = match self {
            VehiclePreset::UGo => (0.15, 25.0, 0.88, 0.75, 10.0, 1.0),
            VehiclePreset::SmallWheeled => (0.05, 20.0, 0.43, 0.51, 10.0, 1.5),
            VehiclePreset::LargeSkidSteer => (0.25, 30.0, 1.38, 1.52, 10.0, 1.0),
        };
        Vehicle {
            name: self.name().to_string(),
            max_step_m,
            max_slope_deg,
            width_m,
            length_m,
            w_infl,
            w_slope,
        }
    }
}

/// A vehicle as requested: a preset (default `u-go`) with any number
/// overridden. With `preset: custom`… there is no such preset: give every
/// number and the name becomes `custom`.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleSpec {
    /// Starting profile; `u-go` when omitted and not every number is given.
    pub preset: Option<VehiclePreset>,
    /// (0, 5] m.
    pub max_step_m: Option<f64>,
    /// (0, 60] degrees.
    pub max_slope_deg: Option<f64>,
    /// (0, 20] m.
    pub width_m: Option<f64>,
    /// (0, 20] m.
    pub length_m: Option<f64>,
    /// [0, 1000].
    pub w_infl: Option<f64>,
    /// (0, 1000].
    pub w_slope: Option<f64>,
}

impl VehicleSpec {
    /// The profile, or the faults with pointers under `prefix`.
    pub fn resolve(&self, prefix: &str) -> Result<Vehicle, Vec<Issue>> {
        let all_given = self.max_step_m.is_some()
            && self.max_slope_deg.is_some()
            && self.width_m.is_some()
            && self.length_m.is_some()
            && self.w_infl.is_some()
            && self.w_slope.is_some();
        let mut v = self.preset.unwrap_or(VehiclePreset::UGo).vehicle();
        if self.preset.is_none() && all_given {
            v.name = "custom".to_string();
        } else if self.max_step_m.is_some()
            || self.max_slope_deg.is_some()
            || self.width_m.is_some()
            || self.length_m.is_some()
            || self.w_infl.is_some()
            || self.w_slope.is_some()
        {
            v.name = format!("{} (modified)", v.name);
        }
        let mut issues = Vec::new();
        let mut take =
            |field: &str, given: Option<f64>, lo: f64, lo_open: bool, hi: f64, out: &mut f64| {
                let Some(x) = given else { return };
                let low_ok = if lo_open { x > lo } else { x >= lo };
                if x.is_finite() && low_ok && x <= hi {
                    *out = x;
                } else {
                    let open = if lo_open { "(" } else { "[" };
                    issues.push(Issue::new(
                        &format!("{prefix}/{field}"),
                        &format!(
                            "{field} must be in {open}{lo}, {hi}], got {}",
                            crate::num::readable(x)
                        ),
                    ));
                }
            };
        take(
            "max_step_m",
            self.max_step_m,
            0.0,
            true,
            5.0,
            &mut v.max_step_m,
        );
        take(
            "max_slope_deg",
            self.max_slope_deg,
            0.0,
            true,
            60.0,
            &mut v.max_slope_deg,
        );
        take("width_m", self.width_m, 0.0, true, 20.0, &mut v.width_m);
        take("length_m", self.length_m, 0.0, true, 20.0, &mut v.length_m);
        take("w_infl", self.w_infl, 0.0, false, 1000.0, &mut v.w_infl);
        // w_slope > 0 keeps every traversable cost positive, which route
        // search heuristics rely on.
        take("w_slope", self.w_slope, 0.0, true, 1000.0, &mut v.w_slope);
        if issues.is_empty() {
            Ok(v)
        } else {
            Err(issues)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_the_thesis_u_go() {
        let v = VehicleSpec::default().resolve("/vehicle").unwrap();
        assert_eq!(v.name, "u-go");
        assert_eq!(
            (v.max_step_m, v.max_slope_deg, v.w_infl, v.w_slope),
            (0.15, 25.0, 10.0, 1.0)
        );
    }

    #[test]
    fn overrides_and_custom_profiles() {
        let spec = VehicleSpec {
            preset: Some(VehiclePreset::LargeSkidSteer),
            max_slope_deg: Some(20.0),
            ..Default::default()
        };
        let v = spec.resolve("/vehicle").unwrap();
        assert_eq!(v.max_slope_deg, 20.0);
        assert_eq!(v.max_step_m, 0.25);
        assert_eq!(v.name, "large-skid-steer (modified)");
        let custom = VehicleSpec {
            preset: None,
            max_step_m: Some(0.1),
            max_slope_deg: Some(15.0),
            width_m: Some(0.5),
            length_m: Some(0.6),
            w_infl: Some(5.0),
            w_slope: Some(2.0),
        };
        assert_eq!(custom.resolve("").unwrap().name, "custom");
    }

    #[test]
    fn out_of_range_numbers_are_named() {
        let spec = VehicleSpec {
            max_step_m: Some(0.0),
            max_slope_deg: Some(f64::NAN),
            w_infl: Some(-1.0),
            ..Default::default()
        };
        let issues = spec.resolve("/vehicle").unwrap_err();
        let pointers: Vec<&str> = issues.iter().map(|i| i.pointer.as_str()).collect();
        assert_eq!(
            pointers,
            [
                "/vehicle/max_step_m",
                "/vehicle/max_slope_deg",
                "/vehicle/w_infl"
            ]
        );
    }
}
