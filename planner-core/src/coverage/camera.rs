//! Pinhole camera model for nadir photo surveys (SPEC §3.1): ground sample
//! distance, image footprint, line spacing and trigger distance.
//!
//! With the camera pointing straight down from altitude `H`, a sensor side of
//! length `w` behind a lens of focal length `f` sees `H·w/f` metres of ground
//! (similar triangles), and one pixel of that side sees that divided by the
//! pixel count.

use serde::{Deserialize, Serialize};

/// How the camera is mounted relative to the direction of flight.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[serde(rename_all = "lowercase")]
pub enum Orientation {
    /// The long image side (width) lies across track: wide swaths, fewer lanes.
    #[default]
    Landscape,
    /// The image height lies across track, the width along track.
    Portrait,
}

/// A frame camera: sensor size, focal length and image size.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Camera {
    pub sensor_width_mm: f64,
    pub sensor_height_mm: f64,
    pub focal_length_mm: f64,
    pub image_width_px: u32,
    pub image_height_px: u32,
    #[serde(default)]
    pub orientation: Orientation,
}

/// Names accepted by [`Camera::preset`].
pub const PRESETS: &[&str] = &[
    "dji_phantom4_pro",
    "dji_phantom4_rtk",
    "dji_phantom3_pro",
    "dji_mavic2_pro",
    "dji_mavic3_enterprise",
    "dji_zenmuse_p1_35mm",
    "sony_rx1r2",
];

impl Default for Camera {
    /// DJI Phantom 4 Pro, the most common survey camera.
    fn default() -> Self {
        Camera::landscape(13.2, 8.8, 8.8, 5472, 3648)
    }
}

impl Camera {
    fn landscape(sw: f64, sh: f64, f: f64, iw: u32, ih: u32) -> Self {
        Camera {
            sensor_width_mm: sw,
            sensor_height_mm: sh,
            focal_length_mm: f,
            image_width_px: iw,
            image_height_px: ih,
            orientation: Orientation::Landscape,
        }
    }

    /// A camera from its published specifications (landscape mounting), by
    /// one of the names in [`PRESETS`].
    pub fn preset(name: &str) -> Option<Camera> {
        Some(match name {
            // 1" CMOS 20 MP, 8.8 mm (24 mm equivalent).
            "dji_phantom4_pro" | "dji_phantom4_rtk" => Camera::default(),
            // 1/2.3" CMOS 12 MP, 3.61 mm (20 mm equivalent).
            "dji_phantom3_pro" => Camera::landscape(6.17, 4.55, 3.61, 4000, 3000),
            // Hasselblad L1D-20c: 1" CMOS 20 MP, 10.26 mm (28 mm equivalent).
            "dji_mavic2_pro" => Camera::landscape(13.2, 8.8, 10.26, 5472, 3648),
            // Wide camera: 4/3 CMOS 20 MP, 12.29 mm (24 mm equivalent).
            "dji_mavic3_enterprise" => Camera::landscape(17.3, 13.0, 12.29, 5280, 3956),
            // Full frame 45 MP with the DL 35 mm F2.8 lens.
            "dji_zenmuse_p1_35mm" => Camera::landscape(35.9, 24.0, 35.0, 8192, 5460),
            // Full frame 42 MP, fixed 35 mm lens.
            "sony_rx1r2" => Camera::landscape(35.9, 24.0, 35.0, 7952, 5304),
            _ => return None,
        })
    }

    /// Checks that every value is finite, positive and plausible for a real
    /// camera. Returns every problem found as `(field, message)`.
    pub fn validate(&self) -> Result<(), Vec<(String, String)>> {
        let mut errors = Vec::new();
        let mut check_mm = |field: &str, v: f64, max: f64| {
            if !v.is_finite() || v <= 0.0 || v > max {
                errors.push((
                    field.to_string(),
                    format!(
                        "must be a number greater than 0 and at most {max} mm (got {})",
                        crate::num::readable(v)
                    ),
                ));
            }
        };
        check_mm("sensor_width_mm", self.sensor_width_mm, 100.0);
        check_mm("sensor_height_mm", self.sensor_height_mm, 100.0);
        check_mm("focal_length_mm", self.focal_length_mm, 1000.0);
        for (field, v) in [
            ("image_width_px", self.image_width_px),
            ("image_height_px", self.image_height_px),
        ] {
            if !(MIN_PX..=MAX_PX).contains(&v) {
                errors.push((
                    field.to_string(),
                    format!("must be between {MIN_PX} and {MAX_PX} pixels (got {v})"),
                ));
            }
        }
        if errors.is_empty() {
            // Real sensors have (nearly) square pixels; a large mismatch means
            // width and height were swapped on one side.
            let pitch_w = self.sensor_width_mm / f64::from(self.image_width_px);
            let pitch_h = self.sensor_height_mm / f64::from(self.image_height_px);
            let ratio = pitch_w / pitch_h;
            if !(0.5..=2.0).contains(&ratio) {
                errors.push((
                    "sensor_height_mm".to_string(),
                    format!(
                        "pixel aspect ratio {:.3} is not plausible: check that sensor and \
                         image width/height are given in the same order",
                        crate::num::readable(ratio)
                    ),
                ));
            }
        }
        if errors.is_empty() {
            Ok(())
        } else {
            Err(errors)
        }
    }

    /// Sensor side (mm) and pixel count lying across track.
    pub(crate) fn across_track(&self) -> (f64, f64) {
        match self.orientation {
            Orientation::Landscape => (self.sensor_width_mm, f64::from(self.image_width_px)),
            Orientation::Portrait => (self.sensor_height_mm, f64::from(self.image_height_px)),
        }
    }

    /// Sensor side (mm) lying along track.
    pub(crate) fn along_track_mm(&self) -> f64 {
        match self.orientation {
            Orientation::Landscape => self.sensor_height_mm,
            Orientation::Portrait => self.sensor_width_mm,
        }
    }
}

const MIN_PX: u32 = 64;
const MAX_PX: u32 = 100_000;

/// Derived survey quantities for one camera, altitude and overlap.
#[derive(Serialize, Clone, Copy, Debug, PartialEq)]
pub struct SurveyGeometry {
    /// Ground sample distance across track, cm per pixel.
    pub gsd_cm_px: f64,
    /// Ground width of one image across track, metres.
    pub footprint_side_m: f64,
    /// Ground length of one image along track, metres.
    pub footprint_front_m: f64,
    /// Distance between neighbouring lanes, metres.
    pub line_spacing_m: f64,
    /// Distance flown between two photos, metres.
    pub trigger_distance_m: f64,
}

/// Survey geometry at `altitude_m` above ground. Overlaps are fractions
/// (0.7 = 70 %); `line_spacing_override_m` replaces the spacing derived from
/// the side overlap. Inputs are expected to be validated by the caller.
pub fn survey_geometry(
    camera: &Camera,
    altitude_m: f64,
    side_overlap: f64,
    front_overlap: f64,
    line_spacing_override_m: Option<f64>,
) -> SurveyGeometry {
    let (across_mm, across_px) = camera.across_track();
    let footprint_side_m = altitude_m * across_mm / camera.focal_length_mm;
    let footprint_front_m = altitude_m * camera.along_track_mm() / camera.focal_length_mm;
    SurveyGeometry {
        gsd_cm_px: footprint_side_m * 100.0 / across_px,
        footprint_side_m,
        footprint_front_m,
        line_spacing_m: line_spacing_override_m.unwrap_or(footprint_side_m * (1.0 - side_overlap)),
        trigger_distance_m: footprint_front_m * (1.0 - front_overlap),
    }
}

/// Altitude above ground (metres) at which the camera has the given GSD.
pub fn altitude_for_gsd(camera: &Camera, gsd_cm_px: f64) -> f64 {
    let (across_mm, across_px) = camera.across_track();
    gsd_cm_px / 100.0 * across_px * camera.focal_length_mm / across_mm
}

/// A lane within this much of a whole number of trigger distances still
/// takes its photo at the far end. Lanes are often whole numbers of line
/// spacings long, which with the usual overlaps are whole numbers of
/// trigger distances, and the mission files round positions to about a
/// millimetre: the far photo must not hang on that rounding.
pub const PHOTO_END_TOLERANCE_M: f64 = 0.01;

/// Photos taken along a lane: one at the start, then one every
/// `trigger_distance_m`, the last within [`PHOTO_END_TOLERANCE_M`] past the
/// end counted. A non-positive or non-finite trigger distance means only
/// the first photo; an empty or invalid lane takes none.
pub fn photo_count(lane_length_m: f64, trigger_distance_m: f64) -> usize {
    if !lane_length_m.is_finite() || lane_length_m < 0.0 {
        return 0;
    }
    if !trigger_distance_m.is_finite() || trigger_distance_m <= 0.0 {
        return 1;
    }
    // `as` saturates.
    ((lane_length_m + PHOTO_END_TOLERANCE_M) / trigger_distance_m).floor() as usize + 1
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn phantom4_at_100m() {
        // Published DJI figure: 2.74 cm/px at 100 m.
        let g = survey_geometry(&Camera::default(), 100.0, 0.7, 0.8, None);
        assert_relative_eq!(
            g.gsd_cm_px,
            100.0 * 13.2 * 100.0 / (5472.0 * 8.8),
            max_relative = 1e-12
        );
        assert!((g.gsd_cm_px - 2.74).abs() < 0.01);
        assert_relative_eq!(g.footprint_side_m, 150.0, max_relative = 1e-12);
        assert_relative_eq!(g.footprint_front_m, 100.0, max_relative = 1e-12);
        assert_relative_eq!(g.line_spacing_m, 45.0, max_relative = 1e-12);
        assert_relative_eq!(g.trigger_distance_m, 20.0, max_relative = 1e-12);
    }

    #[test]
    fn portrait_swaps_sides_and_override() {
        let cam = Camera {
            orientation: Orientation::Portrait,
            ..Camera::default()
        };
        let g = survey_geometry(&cam, 88.0, 0.5, 0.5, Some(12.5));
        assert_relative_eq!(g.footprint_side_m, 88.0, max_relative = 1e-12);
        assert_relative_eq!(g.footprint_front_m, 132.0, max_relative = 1e-12);
        assert_relative_eq!(g.gsd_cm_px, 8800.0 / 3648.0, max_relative = 1e-12);
        assert_eq!(g.line_spacing_m, 12.5);
        assert_relative_eq!(g.trigger_distance_m, 66.0, max_relative = 1e-12);
    }

    #[test]
    fn altitude_for_gsd_inverts_gsd() {
        for name in PRESETS {
            let mut cam = Camera::preset(name).unwrap();
            for orientation in [Orientation::Landscape, Orientation::Portrait] {
                cam.orientation = orientation;
                let h = altitude_for_gsd(&cam, 2.0);
                let g = survey_geometry(&cam, h, 0.7, 0.7, None);
                assert_relative_eq!(g.gsd_cm_px, 2.0, max_relative = 1e-12);
            }
        }
    }

    #[test]
    fn presets_are_valid_and_known() {
        for name in PRESETS {
            let cam = Camera::preset(name).unwrap_or_else(|| panic!("{name}"));
            assert_eq!(cam.validate(), Ok(()), "{name}");
        }
        assert_eq!(Camera::preset("nope"), None);
        assert_eq!(Camera::preset("dji_phantom4_pro"), Some(Camera::default()));
        let p1 = Camera::preset("dji_zenmuse_p1_35mm").unwrap();
        assert_eq!((p1.image_width_px, p1.image_height_px), (8192, 5460));
    }

    #[test]
    fn validate_reports_every_bad_field() {
        let cam = Camera {
            sensor_width_mm: f64::NAN,
            sensor_height_mm: -1.0,
            focal_length_mm: 0.0,
            image_width_px: 0,
            image_height_px: 3000,
            orientation: Orientation::Landscape,
        };
        let errors = cam.validate().unwrap_err();
        let fields: Vec<&str> = errors.iter().map(|(f, _)| f.as_str()).collect();
        assert_eq!(
            fields,
            [
                "sensor_width_mm",
                "sensor_height_mm",
                "focal_length_mm",
                "image_width_px"
            ]
        );
        let swapped = Camera {
            image_width_px: 3648,
            image_height_px: 5472,
            ..Camera::default()
        };
        assert_eq!(swapped.validate().unwrap_err().len(), 1);
    }

    #[test]
    fn serde_round_trip_and_default_orientation() {
        let json = r#"{"sensor_width_mm":13.2,"sensor_height_mm":8.8,"focal_length_mm":8.8,
            "image_width_px":5472,"image_height_px":3648}"#;
        let cam: Camera = serde_json::from_str(json).unwrap();
        assert_eq!(cam, Camera::default());
        let portrait = Camera {
            orientation: Orientation::Portrait,
            ..cam
        };
        let text = serde_json::to_string(&portrait).unwrap();
        assert!(text.contains(r#""orientation":"portrait""#), "{text}");
        assert_eq!(serde_json::from_str::<Camera>(&text).unwrap(), portrait);
    }

    #[test]
    fn photos_along_a_lane() {
        assert_eq!(photo_count(100.0, 20.0), 6);
        assert_eq!(photo_count(99.9, 20.0), 5);
        // Rounding of a lane of exactly 5 trigger distances, either way.
        assert_eq!(photo_count(100.0 - 0.002, 20.0), 6);
        assert_eq!(photo_count(100.0 + 0.002, 20.0), 6);
        assert_eq!(photo_count(100.0 - 0.011, 20.0), 5);
        assert_eq!(photo_count(0.0, 20.0), 1);
        assert_eq!(photo_count(0.3 * 3.0, 0.3), 4);
        assert_eq!(photo_count(50.0, 0.0), 1);
        assert_eq!(photo_count(f64::NAN, 10.0), 0);
    }
}
