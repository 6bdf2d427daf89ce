//! The ground footprint of a camera pitched forward along the flight
//! direction (oblique imagery): a trapezoid on flat ground, and the lane
//! spacing and trigger distance it gives.
//!
//! In a frame with `x` across track (right), `y` along track (ahead) and
//! `z` up, a camera `H` above the ground tilted `t` from the nadir
//! (`t = 90° + camera_pitch_deg`) has its optical axis along
//! `A = (0, sin t, −cos t)` and its image "up" along `U = (0, cos t, sin t)`.
//! A sensor point `(sx, sy)` (mm, `sy` towards the far edge) sees along
//! `sx·X + sy·U + f·A`, which meets the ground at
//! `k = H / (f·cos t − sy·sin t)`: the point `(k·sx, k·(sy·cos t + f·sin t))`.
//! A sensor row has one `k`, so each image row is a straight ground line
//! `k·w` wide: the footprint is a trapezoid, narrowest at its near edge.

use super::camera::{Camera, SurveyGeometry, survey_geometry};

/// Steepest allowed pitch: the camera straight down.
pub const NADIR_PITCH_DEG: f64 = -90.0;
/// Least steep allowed pitch.
pub const MIN_PITCH_DEG: f64 = -30.0;
/// The footprint's far edge must look at least this far below the horizon:
/// nearer it, the footprint (and with it the trigger distance) grows
/// without bound.
pub const FAR_EDGE_BELOW_HORIZON_DEG: f64 = 5.0;

/// A pitch the camera cannot fly: its far edge would look at or above
/// [`FAR_EDGE_BELOW_HORIZON_DEG`] below the horizon.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error(
    "at camera_pitch_deg {pitch_deg} the far edge of the image looks less than \
     {FAR_EDGE_BELOW_HORIZON_DEG}° below the horizon (its footprint has no useful end): with this \
     camera the pitch must be at most {steepest_allowed_deg:.1}"
)]
pub struct PitchTooShallow {
    pub pitch_deg: f64,
    /// The least steep pitch this camera allows.
    pub steepest_allowed_deg: f64,
}

/// Tilt from the nadir, radians, of a pitch in degrees.
fn tilt(pitch_deg: f64) -> f64 {
    (90.0 + pitch_deg).to_radians()
}

/// Half the field of view along track, radians.
fn half_fov_along(camera: &Camera) -> f64 {
    (camera.along_track_mm() / 2.0 / camera.focal_length_mm).atan()
}

/// The least steep pitch `camera` may fly (see [`PitchTooShallow`]).
pub fn least_steep_pitch_deg(camera: &Camera) -> f64 {
    let max_tilt = 90.0 - FAR_EDGE_BELOW_HORIZON_DEG - half_fov_along(camera).to_degrees();
    (max_tilt - 90.0).clamp(NADIR_PITCH_DEG, MIN_PITCH_DEG)
}

/// The ground point seen by sensor point `(sx, sy)` (mm), as (across,
/// along) metres from the point under the camera; `None` when the ray does
/// not meet the ground ahead.
fn ground_point(camera: &Camera, altitude_m: f64, t: f64, sx: f64, sy: f64) -> Option<[f64; 2]> {
    let f = camera.focal_length_mm;
    let denom = f * t.cos() - sy * t.sin();
    (denom > 0.0).then(|| {
        let k = altitude_m / denom;
        [k * sx, k * (sy * t.cos() + f * t.sin())]
    })
}

/// The footprint's corners on flat ground `altitude_m` below the camera, as
/// (across, along) metres from the point under it: near left, near right,
/// far right, far left.
pub fn footprint_corners(
    camera: &Camera,
    altitude_m: f64,
    pitch_deg: f64,
) -> Result<[[f64; 2]; 4], PitchTooShallow> {
    check_pitch(camera, pitch_deg)?;
    let t = tilt(pitch_deg);
    let (w, h) = (camera.across_track().0 / 2.0, camera.along_track_mm() / 2.0);
    let corner = |sx: f64, sy: f64| {
        ground_point(camera, altitude_m, t, sx, sy).ok_or(PitchTooShallow {
            pitch_deg,
            steepest_allowed_deg: least_steep_pitch_deg(camera),
        })
    };
    Ok([
        corner(-w, -h)?,
        corner(w, -h)?,
        corner(w, h)?,
        corner(-w, h)?,
    ])
}

fn check_pitch(camera: &Camera, pitch_deg: f64) -> Result<(), PitchTooShallow> {
    let far = tilt(pitch_deg) + half_fov_along(camera);
    if far.to_degrees() > 90.0 - FAR_EDGE_BELOW_HORIZON_DEG + 1e-9 {
        return Err(PitchTooShallow {
            pitch_deg,
            steepest_allowed_deg: least_steep_pitch_deg(camera),
        });
    }
    Ok(())
}

/// [`survey_geometry`] for a camera pitched `pitch_deg` (−90 nadir … −30),
/// forward along the lanes, over flat ground `altitude_m` below:
///
/// - `footprint_front_m` is the trapezoid's extent along track, and the
///   trigger distance that extent less the front overlap;
/// - `footprint_side_m` is its width at the near edge, and the spacing that
///   width less the side overlap. The near edge is the narrowest row, so
///   the requested side overlap holds for every row of the image — the
///   centre's width would leave the near rows (the finest GSD, most of a
///   3D model's detail) under-overlapped;
/// - `gsd_cm_px` is the across-track GSD at the image centre, whose slant
///   range is `H / cos t`.
///
/// At −90 this is [`survey_geometry`] exactly.
pub fn pitched_geometry(
    camera: &Camera,
    altitude_m: f64,
    pitch_deg: f64,
    side_overlap: f64,
    front_overlap: f64,
    line_spacing_override_m: Option<f64>,
) -> Result<SurveyGeometry, PitchTooShallow> {
    if pitch_deg <= NADIR_PITCH_DEG {
        return Ok(survey_geometry(
            camera,
            altitude_m,
            side_overlap,
            front_overlap,
            line_spacing_override_m,
        ));
    }
    let [near_left, near_right, far_right, _] = footprint_corners(camera, altitude_m, pitch_deg)?;
    let footprint_side_m = near_right[0] - near_left[0];
    let footprint_front_m = far_right[1] - near_right[1];
    let (across_mm, across_px) = camera.across_track();
    let centre_gsd_m = altitude_m / tilt(pitch_deg).cos() * across_mm / camera.focal_length_mm;
    Ok(SurveyGeometry {
        gsd_cm_px: centre_gsd_m * 100.0 / across_px,
        footprint_side_m,
        footprint_front_m,
        line_spacing_m: line_spacing_override_m.unwrap_or(footprint_side_m * (1.0 - side_overlap)),
        trigger_distance_m: footprint_front_m * (1.0 - front_overlap),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// Independent ray casting: rotate the camera ray by the tilt about the
    /// across-track axis and intersect it with z = 0.
    fn cast(camera: &Camera, h: f64, pitch: f64, sx: f64, sy: f64) -> [f64; 2] {
        // Camera looking straight down: ray (sx, sy, −f); tilt forward
        // (towards +y) by t is a rotation about x.
        let t = (90.0 + pitch).to_radians();
        let (x, y, z) = (sx, sy, -camera.focal_length_mm);
        let (y2, z2) = (y * t.cos() - z * t.sin(), y * t.sin() + z * t.cos());
        let k = h / -z2;
        [x * k, y2 * k]
    }

    #[test]
    fn nadir_is_the_nadir_geometry() {
        let cam = Camera::default();
        let a = pitched_geometry(&cam, 80.0, -90.0, 0.7, 0.8, None).unwrap();
        assert_eq!(a, survey_geometry(&cam, 80.0, 0.7, 0.8, None));
        // The footprint at −90 by the oblique formulas: the same rectangle.
        let c = footprint_corners(&cam, 100.0, -90.0).unwrap();
        assert_relative_eq!(c[1][0] - c[0][0], 150.0, max_relative = 1e-12);
        assert_relative_eq!(c[2][1] - c[1][1], 100.0, max_relative = 1e-12);
    }

    #[test]
    fn corners_match_rotated_rays() {
        let cam = Camera::default();
        let (w, h) = (13.2 / 2.0, 8.8 / 2.0);
        for pitch in [-80.0, -60.0, -45.0, -35.0] {
            let c = footprint_corners(&cam, 70.0, pitch).unwrap();
            let want = [
                cast(&cam, 70.0, pitch, -w, -h),
                cast(&cam, 70.0, pitch, w, -h),
                cast(&cam, 70.0, pitch, w, h),
                cast(&cam, 70.0, pitch, -w, h),
            ];
            for (got, want) in c.iter().zip(want) {
                assert_relative_eq!(got[0], want[0], max_relative = 1e-9);
                assert_relative_eq!(got[1], want[1], max_relative = 1e-9);
            }
            // A trapezoid: narrower near, wider far, symmetric across.
            assert!(c[1][0] - c[0][0] < c[2][0] - c[3][0], "{pitch}");
            assert_relative_eq!(c[0][0], -c[1][0], max_relative = 1e-12);
        }
    }

    #[test]
    fn oblique_spacing_and_trigger() {
        let cam = Camera::default();
        // −45°: t = 45°, half FOV along = atan(0.5); near edge at
        // H·tan(45° − 26.57°), far at H·tan(71.57°) = 3H.
        let g = pitched_geometry(&cam, 100.0, -45.0, 0.5, 0.6, None).unwrap();
        let a = 0.5f64.atan();
        let t = 45f64.to_radians();
        let along = 100.0 * ((t + a).tan() - (t - a).tan());
        assert_relative_eq!(g.footprint_front_m, along, max_relative = 1e-12);
        assert_relative_eq!(g.trigger_distance_m, along * 0.4, max_relative = 1e-12);
        let near = 100.0 * 13.2 / (8.8 * t.cos() + 4.4 * t.sin());
        assert_relative_eq!(g.footprint_side_m, near, max_relative = 1e-12);
        assert_relative_eq!(g.line_spacing_m, near * 0.5, max_relative = 1e-12);
        // Oblique sees more ground than nadir at the same height.
        let nadir = survey_geometry(&cam, 100.0, 0.5, 0.6, None);
        assert!(g.footprint_front_m > nadir.footprint_front_m);
        assert!(g.gsd_cm_px > nadir.gsd_cm_px);
    }

    #[test]
    fn too_shallow_is_refused_with_the_limit() {
        let cam = Camera::default();
        // Half FOV along 26.57°: tilt at most 90 − 5 − 26.57 = 58.43°.
        let least = least_steep_pitch_deg(&cam);
        assert_relative_eq!(least, -90.0 + 58.43, epsilon = 0.01);
        let e = pitched_geometry(&cam, 60.0, -30.0, 0.7, 0.8, None).unwrap_err();
        assert_relative_eq!(e.steepest_allowed_deg, least, max_relative = 1e-12);
        assert!(e.to_string().contains("at most -31.6"), "{e}");
        assert!(pitched_geometry(&cam, 60.0, least, 0.7, 0.8, None).is_ok());
        // A long lens allows −30.
        let tele = Camera::preset("sony_rx1r2").unwrap();
        assert!(pitched_geometry(&tele, 60.0, -30.0, 0.7, 0.8, None).is_ok());
    }
}
